"""Issue 24, memory: a long SITL flight does not grow the autopilot's or the vehicle's resident
memory (< 50 MB an hour each), with the rerun recorder on.

The real two-process SITL (lockstep, UDP, case 0, the autopilot's rerun recorder writing
``run.rrd`` as in every run) flies ``DURATION_S`` of *simulated* time while this process
samples the resident set size (``VmRSS`` of ``/proc/PID/status``) of the two processes it
started, each sample paired with the simulated time the ground station sees. The slope is a
straight-line fit of RSS against simulated time over the last 610 simulated seconds of the
flight, extrapolated to one hour.

Why simulated time measures the leak: what grew (rerun's per-chunk footer manifest, the flown
path re-sent whole; see :mod:`vtolftc.telemetry.recording`) grows per row logged, and the
recorder logs rows per *simulated* second (50 Hz, sent every 0.5 simulated s), so an hour of
lockstep flight logs what an hour of real-time flight logs; lockstep only runs it faster than
real time. The few wall-clock-driven parts (the recorder's 0.25 s background flush, the ground
station's streams) run at most as often per simulated second as in real time whenever lockstep
is faster than real time.

The issue allows extrapolating only a slope measured over >= 10 min of flight, so this test
flies ``DURATION_S`` = 12 simulated minutes and fits the last ``DURATION_S - FIT_FROM_S`` =
610 s (after take-off, transition and warm-up). That takes about 2.5 wall minutes on an idle
2-core machine (lockstep runs about 5x real time with the recorder on) and up to about 10 on
a heavily loaded one. Samples are taken every simulated second (polled often in wall time,
:func:`~vtolftc.runners.memory_probe.fly_sampled`), so their number does not depend on how
fast the machine runs the flight. Sensitivity: 50 MB/h is 8.5 MB over the fit; the leak it
guards against (138 KB per simulated second before the fix) is 84 MB.
``python benchmarks/bench_memory.py`` flies the same with the recorder on and off and prints
the table in its docstring.
"""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.runners.memory_probe import fly_sampled, slope_mb_per_h
from vtolftc.runners.sitl import SitlConfig

DURATION_S = 720.0
"""Simulated seconds flown."""
FIT_FROM_S = 110.0
"""Simulated time [s] from which the slope is fitted: the fit spans >= 10 simulated minutes."""
LIMIT_MB_PER_H = 50.0


def test_slope_fit_sees_a_leak_and_ignores_a_warm_up():
    t = np.linspace(0.0, 180.0, 200)
    warm = np.where(t < 60.0, 200_000.0 + 500.0 * t, 230_000.0)       # grows, then flat
    assert abs(slope_mb_per_h(t, warm)) < 1e-6
    leak = warm + 138.0 * t                                           # 138 KB/s: 485 MB/h
    assert slope_mb_per_h(t, leak) == pytest.approx(138.0 * 3600 / 1024)


@pytest.mark.slow
def test_sitl_resident_memory_stays_flat_with_the_recorder_on(tmp_path):
    cfg = SitlConfig(case="0", controller="gs-shif", transport="udp", realtime=False,
                     duration_s=DURATION_S, out_dir=tmp_path, plots=False)
    data, res = fly_sampled(cfg, every_sim_s=1.0)
    assert res.sim_time_s >= DURATION_S - 0.01
    fit = data[data[:, 0] >= FIT_FROM_S]
    span = fit[-1, 0] - fit[0, 0]
    assert span >= 600.0, f"the fit spans only {span:.0f} simulated s"
    assert len(fit) >= 300, f"only {len(fit)} samples over {span:.0f} simulated s"
    assert (tmp_path / "autopilot" / "run.rrd").stat().st_size > 1_000_000   # it recorded
    for j, name in ((1, "autopilot"), (2, "vehicle")):
        growth = slope_mb_per_h(fit[:, 0], fit[:, j], from_s=FIT_FROM_S)
        print(f"{name}: {growth:.1f} MB per simulated hour, {len(fit)} samples over "
              f"{span:.0f} simulated s")       # shown with pytest -s
        assert growth < LIMIT_MB_PER_H, (
            f"{name}: {growth:.1f} MB per simulated hour (RSS {fit[0, j] / 1024:.0f} -> "
            f"{fit[-1, j] / 1024:.0f} MB over simulated {fit[0, 0]:.0f}-{fit[-1, 0]:.0f} s)")


def test_autopilot_process_records_rerun_unless_no_rerun(tmp_path):
    """``--no-rerun`` (the memory benchmark's recorder-off figure) leaves only the recorder
    out of the autopilot process's observers."""
    from vtolftc.runners.processes.autopilot import _parse_args, run_observers
    from vtolftc.telemetry.recording import RerunRecorder

    for flag, want in (([], True), (["--no-rerun"], False)):
        args = _parse_args(["--hil-link", "udpin:127.0.0.1:1", *flag])
        obs = run_observers(tmp_path / str(want), plots=False, rerun=not args.no_rerun)
        try:
            assert any(isinstance(o, RerunRecorder) for o in obs) == want
            assert len(obs) == 2 + want
        finally:
            for o in obs:
                if isinstance(o, RerunRecorder):
                    o.close()
