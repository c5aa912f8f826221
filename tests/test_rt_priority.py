"""``--rt-priority N`` of the SITL process programs (:mod:`vtolftc.runners.processes.priority`):
once applied (when the process is compiled and ready), every thread of the process and every
thread started afterwards runs as SCHED_FIFO at N where permitted; an invalid N is one line
and exit status 2."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from support.procs import zenoh_probe

from vtolftc.runners.processes.priority import check_rt_priority, thread_priorities

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


def test_zenoh_runtime_threads_one_above_the_rest():
    """zenoh's tokio workers (rx/tx/app/acc/net-N) at N + 1, capped at the maximum; Python's
    threads, rerun's ``tokio-rt-worker`` and names that only look alike at N."""
    names = {1: "python", 2: "rx-0", 3: "rx-1", 4: "tx-0", 5: "app-0", 6: "acc-12",
             7: "net-3", 8: "tokio-rt-worker", 9: "zenoh-recv-watchdog", 10: "rx-", 11: "rx-0a",
             12: "xrx-0", 13: "", 14: "ChunkBatcher::c", 15: "rx0"}
    zenoh = {2, 3, 4, 5, 6, 7}
    assert thread_priorities(10, names) == {t: 11 if t in zenoh else 10 for t in names}
    top = os.sched_get_priority_max(os.SCHED_FIFO)
    assert thread_priorities(top, names) == dict.fromkeys(names, top)
    assert thread_priorities(1, {4: "tx-0"}) == {4: 2}


def test_a_zenoh_process_runs_zenoh_threads_one_above_when_permitted():
    got = zenoh_probe("priority.apply_rt_priority(7)",
                      "os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority")
    if not got.applied:
        assert got.lines[0].startswith("probe: --rt-priority 7 not applied"), got.lines
        pytest.skip("SCHED_FIFO not permitted on this machine")
    assert got.zenoh and got.others, got.threads
    assert all(t[1:] == [str(os.SCHED_FIFO), "8"] for t in got.zenoh), got.threads
    assert all(t[1:] == [str(os.SCHED_FIFO), "7"] for t in got.others), got.threads
    assert got.lines[0] == (f"probe: SCHED_FIFO priority 7 ({len(got.threads)} threads), "
                            f"zenoh's {len(got.zenoh)} runtime threads at 8"), got.lines[0]
    assert got.linked, got.lines


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
