"""``vtolftc sitl`` input checks (no processes are started for bad input) and the runner's
URL plan (loopback only, free ports, both transports)."""

from __future__ import annotations

import pytest

from protocols import parse_link_url
from vtolftc.cli import run as cli_run
from vtolftc.sitl import SitlConfig, SitlRun


@pytest.mark.parametrize("argv, fragment", [
    (["sitl", "--case", "7"], "--case '7': expected one of 0, 1, 2"),
    (["sitl", "--transport", "tcp"], "expected udp or zenoh"),
    (["sitl", "--controller", "pid"], "expected gs-shif, shif or lqr"),
    (["sitl", "--duration", "-3"], "--duration"),
    (["sitl", "--duration", "nan"], "--duration"),
])
def test_sitl_cli_rejects_bad_input(argv, fragment, capsys, tmp_path):
    assert cli_run([*argv, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err
    assert not (tmp_path / "run").exists()  # nothing started


@pytest.mark.parametrize("transport", ["udp", "zenoh"])
def test_link_plan_is_loopback_and_consistent(transport, tmp_path):
    run = SitlRun(SitlConfig(transport=transport, out_dir=tmp_path))
    vehicle, ap_hil, ap_gcs, gs = (parse_link_url(u) for u in run._urls())
    if transport == "udp":
        assert vehicle.scheme == gs.scheme == "udp-server"
        assert ap_hil.scheme == ap_gcs.scheme == "udp-client"
        assert vehicle.port == ap_hil.port and ap_gcs.port == gs.port != vehicle.port
        assert {u.host for u in (vehicle, ap_hil, ap_gcs, gs)} == {"127.0.0.1"}
    else:
        assert (vehicle.link, vehicle.direction, ap_hil.direction) == ("hil", "up", "down")
        assert (ap_gcs.link, ap_gcs.direction, gs.direction) == ("gcs", "up", "down")
        assert vehicle.listen == tuple(e for e in ap_hil.connect)
        assert ap_gcs.listen == gs.connect
        assert all(e.startswith("tcp/127.0.0.1:") for e in vehicle.listen + ap_gcs.listen)
    with pytest.raises(ValueError, match="udp or zenoh"):
        SitlRun(SitlConfig(transport="serial"))
