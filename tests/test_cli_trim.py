"""`vtolftc trim` prints the trim table at the paper's airspeeds."""

from __future__ import annotations

import json

from vtolftc.cli.main import main


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


def test_malformed_trim_arguments_one_line_exit_2(capsys):
    """Issue 25: ``--airspeeds x,y`` ended in a traceback; every malformed list (and a
    non-finite altitude or pitch) is one line on stderr and exit status 2."""
    for argv in (["--airspeeds", "x,y"], ["--airspeeds", ""], ["--airspeeds", "0,,4"],
                 ["--airspeeds", " , "], ["--airspeeds", "4;7"], ["--airspeeds", "nan"],
                 ["--airspeeds", "1e999"], ["--airspeeds", "0x12"],
                 ["--altitude", "nan"], ["--altitude", "inf"],
                 ["--transition-pitch-deg", "nan"]):
        assert main(["trim", *argv]) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("vtolftc trim: error: --") and err.count("\n") == 1, (argv, err)
        assert "Traceback" not in err
