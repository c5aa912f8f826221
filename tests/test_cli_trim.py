"""`vtolftc trim` prints the trim table at the paper's airspeeds."""

from __future__ import annotations

import json

from vtolftc.cli import main


def test_trim_table_markdown(capsys):
    assert main(["trim"]) == 0
    out = capsys.readouterr().out
    for v in ("| 0 | hover", "| 4 | rotor-assisted", "| 13 | wing", "| 18 | wing"):
        assert v in out


def test_trim_json_and_bad_airspeed(capsys):
    assert main(["trim", "--json", "--airspeeds", "0,18"]) == 0
    doc = json.loads(capsys.readouterr().out)
    cruise = next(t for t in doc["trims"] if t["airspeed_m_s"] == 18.0 and t["mode"] == "wing")
    assert cruise["feasible"] and abs(cruise["elevator_deg"]) < 10
    assert main(["trim", "--airspeeds", "0,-4"]) == 2
    assert "is not an airspeed" in capsys.readouterr().err
