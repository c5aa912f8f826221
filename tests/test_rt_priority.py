"""``--rt-priority N`` of the SITL process programs (:mod:`vtolftc.runners.processes.priority`):
once applied (when the process is compiled and ready), every thread of the process and every
thread started afterwards runs as SCHED_FIFO at N where permitted; an invalid N is one line
and exit status 2."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from vtolftc.runners.processes.priority import check_rt_priority

_CHILD = """
import os, sys, threading
from vtolftc.runners.processes.priority import apply_rt_priority
policy = lambda: (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
go, seen = threading.Event(), {}
def early():
    go.wait(); seen["early"] = policy()
th = threading.Thread(target=early); th.start()   # a thread that exists before the call
ok = apply_rt_priority(7, "probe", sys.stdout)
go.set(); th.join()
later = threading.Thread(target=lambda: seen.update(later=policy())); later.start(); later.join()
print("main", *policy()); print("early", *seen["early"]); print("later", *seen["later"])
print("ok", ok)
"""


@pytest.mark.parametrize("n, valid", [(0, True), (1, True), (10, True), (99, True),
                                      (100, False), (-1, False)])
def test_valid_priorities_are_off_and_the_fifo_range(n, valid):
    assert (check_rt_priority(n) is None) == valid


def test_every_thread_of_the_process_runs_as_fifo_when_permitted():
    """The threads that exist at the call (the autopilot's ground-station threads) and those
    started afterwards."""
    out = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True,
                         timeout=60, check=True).stdout.splitlines()
    if out[-1] != "ok True":  # no CAP_SYS_NICE here: said in one line, ordinary scheduling
        assert out[0].startswith("probe: --rt-priority 7 not applied"), out
        assert out[1:4] == [f"{w} {os.SCHED_OTHER} 0" for w in ("main", "early", "later")]
        pytest.skip("SCHED_FIFO not permitted on this machine")
    assert out[0] == "probe: SCHED_FIFO priority 7 (2 threads)"
    assert out[1:4] == [f"{w} {os.SCHED_FIFO} 7" for w in ("main", "early", "later")], out


@pytest.mark.parametrize("program, args", [
    ("vehicle", ["--link", "udp-server://127.0.0.1:9"]),
    ("autopilot", ["--hil-link", "udp-client://127.0.0.1:9"])])
def test_bad_rt_priority_is_one_line_and_exit_2(program, args):
    p = subprocess.run([sys.executable, "-m", f"vtolftc.runners.processes.{program}", *args,
                        "--rt-priority", "100"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [
        f"{program}: error: --rt-priority 100: expected 0 (off) or a SCHED_FIFO priority in "
        "[1, 99]"]
