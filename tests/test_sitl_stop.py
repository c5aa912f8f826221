""":meth:`vtolftc.runners.sitl.SitlRun.stop`: a process that does not end by itself after
SIGTERM leaves evidence of what it was doing, then is killed."""

from __future__ import annotations

import signal
import time

from vtolftc.runners.sitl import SitlConfig, SitlRun


def test_stop_writes_what_a_process_ignoring_sigterm_was_doing_then_kills_it(tmp_path):
    """The teardown's evidence: a child that ignores SIGTERM and keeps computing gets, after
    the grace, its Python stack (faulthandler, on DUMP_SIGNAL) and its threads' states with the
    CPU they used over half a second written to its log, then SIGKILL (exit -9)."""
    run = SitlRun(SitlConfig(out_dir=tmp_path, plots=False))
    try:
        run._spawn("vehicle", ["-c", "import signal, time; "
                               "from vtolftc.runners.processes.procstate import "
                               "enable_stack_dump; enable_stack_dump(); "
                               "signal.signal(signal.SIGTERM, signal.SIG_IGN); "
                               "print('up', flush=True)\n"
                               "def busy_after_stop():\n"
                               "    while True: sum(range(1000))\n"
                               "busy_after_stop()"])
        log = tmp_path / "vehicle.log"
        deadline = time.monotonic() + 60.0
        while "up" not in log.read_text() and time.monotonic() < deadline:
            time.sleep(0.05)
        pid = run.procs["vehicle"].pid
        run.stop(grace_s=0.5)
        assert run.procs["vehicle"].returncode == -signal.SIGKILL
        text = log.read_text()
        assert "runner: vehicle still running 0.5 s after SIGTERM; its Python stacks" in text
        assert "runner: sending vehicle SIGKILL; its threads:" in text
        # faulthandler's dump of the main thread: where the Python code was
        assert "Current thread" in text and "in busy_after_stop" in text, text
        line = next(ln for ln in text.splitlines() if ln.startswith(f"{pid} python"))
        assert " R cpu " in line and " wchan " in line, line  # running, the main thread
        assert " s in 0.5 s)" in line and "(+0.00 s" not in line, line  # it used CPU meanwhile
    finally:
        run.close()

