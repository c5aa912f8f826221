""":meth:`vtolftc.runners.sitl.SitlRun.stop`: a process that does not end by itself after
SIGTERM leaves evidence of what it was doing, then is killed."""

from __future__ import annotations

import signal
import time

from vtolftc.runners.sitl import SitlConfig, SitlRun


def test_stop_writes_what_a_process_ignoring_sigterm_was_doing_then_kills_it(tmp_path):
    """The teardown's evidence: a child that ignores SIGTERM gets, after the grace, its
    threads' states written to its log, then SIGKILL (exit -9)."""
    run = SitlRun(SitlConfig(out_dir=tmp_path, plots=False))
    try:
        run._spawn("vehicle", ["-c", "import signal, time; "
                               "signal.signal(signal.SIGTERM, signal.SIG_IGN); "
                               "print('up', flush=True); time.sleep(120)"])
        log = tmp_path / "vehicle.log"
        deadline = time.monotonic() + 60.0
        while "up" not in log.read_text() and time.monotonic() < deadline:
            time.sleep(0.05)
        pid = run.procs["vehicle"].pid
        run.stop(grace_s=0.5)
        assert run.procs["vehicle"].returncode == -signal.SIGKILL
        text = log.read_text()
        assert "runner: vehicle still running 0.5 s after SIGTERM, sending SIGKILL" in text
        assert f"\n{pid} python" in text and " wchan " in text, text  # the main thread's line
    finally:
        run.close()

