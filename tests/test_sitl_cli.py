"""``vtolftc sitl`` input checks (no processes are started for bad input) and the runner's
URL plan (loopback only, free ports, both transports)."""

from __future__ import annotations

import pytest
from support.procs import sitl_command_lines

from vtolftc.cli.main import run as cli_run
from vtolftc.protocols import parse_link_url
from vtolftc.runners.sitl import SitlConfig, SitlRun


@pytest.mark.parametrize("argv, fragment", [
    (["sitl", "--case", "7"], "--case '7': expected one of 0, 1, 2"),
    (["sitl", "--transport", "tcp"], "expected udp or zenoh"),
    (["sitl", "--controller", "pid"], "expected gs-shif, shif or lqr"),
    (["sitl", "--duration", "-3"], "--duration"),
    (["sitl", "--duration", "nan"], "--duration"),
    (["sitl", "--rt-priority", "100"], "--rt-priority 100: expected 0 (off) or a SCHED_FIFO"),
    (["sitl", "--rt-priority", "-1"], "--rt-priority -1"),
    (["sitl", "--spin-us", "-5"], "--spin-us -5.0: expected 0 <= microseconds"),
    (["sitl", "--spin-us", "nan"], "--spin-us nan"),
    (["sitl", "--cpus", "0"], "--cpus '0': expected two CPU numbers"),
    (["sitl", "--cpus", "0,x"], "--cpus '0,x': expected two CPU numbers"),
    (["sitl", "--cpus", "0,4096"], "--cpus '0,4096': CPU 4096 is not one"),
    (["sitl", "--cpus=-1,0"], "--cpus '-1,0': CPU -1 is not one"),
    (["sitl", "--cpus", "0,0"], "need different CPUs"),
    (["sitl", "--zenoh-peer-cpu"], "--zenoh-peer-cpu needs --cpus A,V"),
])
def test_sitl_cli_rejects_bad_input(argv, fragment, capsys, tmp_path):
    assert cli_run([*argv, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err
    assert not (tmp_path / "run").exists()  # nothing started


@pytest.mark.parametrize("transport, low", [("udp", False), ("zenoh", False), ("udp", True),
                                            ("zenoh", True)])
def test_link_plan_is_loopback_and_consistent(transport, low, tmp_path):
    """``zenoh_lowlatency``: both ends of the HIL link (zenoh only), not the ground station's."""
    run = SitlRun(SitlConfig(transport=transport, out_dir=tmp_path, zenoh_lowlatency=low))
    vehicle, ap_hil, ap_gcs, gs = (parse_link_url(u) for u in run._urls())
    want = low and transport == "zenoh"
    assert [u.lowlatency for u in (vehicle, ap_hil, ap_gcs, gs)] == [want, want, False, False]
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


def test_rt_priority_reaches_both_processes_and_only_when_asked(tmp_path, monkeypatch):
    """``SitlConfig.rt_priority`` (``vtolftc sitl --rt-priority N``) is passed to both programs'
    command lines; the default (0) passes nothing. No process is started."""
    for prio, want in ((0, None), (12, "12")):
        argv = sitl_command_lines(monkeypatch,
                                  SitlConfig(out_dir=tmp_path / str(prio), rt_priority=prio))
        for name, args in argv.items():
            got = args[args.index("--rt-priority") + 1] if "--rt-priority" in args else None
            assert got == want, (name, prio, args)


@pytest.mark.slow
def test_sitl_dashboard_flag_serves_the_page_and_follows_the_run(tmp_path, monkeypatch, capsys):
    """``vtolftc sitl --dashboard``: the dashboard gets its own ground-station link, sees the
    flight's telemetry, and is closed with the run."""
    import vtolftc.dashboard.web as web

    made: list[web.Dashboard] = []

    class Spy(web.Dashboard):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            made.append(self)

    monkeypatch.setattr(web, "Dashboard", Spy)
    rc = cli_run(["sitl", "--case", "0", "--duration", "8", "--dashboard",
                  "--dashboard-port", "0", "--out", str(tmp_path / "run")])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert f"dashboard: {made[0].page_url}" in out and "127.0.0.1" in made[0].page_url
    snap = made[0].gs.snapshot()
    assert snap.armed and snap.sim_time_s > 4.0 and snap.altitude_m > 1.0


def test_sitl_cli_passes_spin_and_cpus_to_the_config(tmp_path, monkeypatch):
    """``vtolftc sitl --spin-us 300 --cpus 0,1`` reaches ``SitlConfig`` (autopilot on the first
    CPU, vehicle on the second); without them, no spin and nothing pinned. ``run_sitl`` is
    replaced: no process is started."""
    import os

    import vtolftc.runners.sitl as sitl_mod

    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        pytest.skip("needs two CPUs this process may use")
    seen: list[SitlConfig] = []

    class StopRunError(Exception):
        pass

    def fake_run(cfg, scenario):
        seen.append(cfg)
        raise StopRunError

    monkeypatch.setattr(sitl_mod, "run_sitl", fake_run)
    a, v = cpus[1], cpus[0]
    for argv in ([], ["--spin-us", "300", "--cpus", f"{a},{v}", "--zenoh-lowlatency",
                      "--zenoh-peer-cpu"]):
        with pytest.raises(StopRunError):
            cli_run(["sitl", "--out", str(tmp_path / str(len(argv))), *argv])
    assert (seen[0].spin_us, seen[0].autopilot_cpu, seen[0].vehicle_cpu,
            seen[0].zenoh_lowlatency) == (0.0, -1, -1, False)
    assert (seen[1].spin_us, seen[1].autopilot_cpu, seen[1].vehicle_cpu,
            seen[1].zenoh_lowlatency) == (300.0, a, v, True)
    assert (seen[0].zenoh_peer_cpu, seen[1].zenoh_peer_cpu) == (False, True)
