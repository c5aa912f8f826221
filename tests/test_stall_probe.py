"""The SITL tests' stall probe (:mod:`support.stall_probe`) against a progress it controls."""

from __future__ import annotations

import os
import threading
import time

from support.stall_probe import StallProbe, proc_threads


def test_proc_threads_sees_a_busy_thread_of_this_process():
    """A thread that spins shows up with its name, state R or S, and CPU time growing."""
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            pass

    th = threading.Thread(target=spin, name="probe-spin", daemon=True)
    th.start()
    try:
        t0 = {tid: cpu for tid, _, _, cpu, _ in proc_threads(os.getpid())}
        time.sleep(0.5)
        rows = proc_threads(os.getpid())
    finally:
        stop.set()
        th.join()
    assert th.native_id in {tid for tid, *_ in rows}
    row = next(r for r in rows if r[0] == th.native_id)
    assert row[1] in ("probe-spin", "python")          # Python names OS threads from 3.14
    assert row[2] in ("R", "S")
    assert row[3] > t0.get(th.native_id, 0.0)
    assert proc_threads(2**22 + 12345) == []          # no such process


def test_a_stall_is_reported_while_it_lasts_and_timed_when_it_ends(tmp_path):
    """Progress moves, stands still 1.2 s (threshold 0.5 s), moves again: one stall, its
    report written during the stall with this process's threads, its duration measured."""
    state = {"p": 0.0, "moving": True}

    def progress() -> float:
        if state["moving"]:
            state["p"] += 0.1
        return state["p"]

    probe = StallProbe(progress, {"me": os.getpid()}, tmp_path, stall_s=0.5, period_s=0.05,
                       history_s=2.0)
    with probe:
        time.sleep(0.5)
        assert probe.stalls == []
        state["moving"] = False
        t0 = time.monotonic()
        while not probe.stalls and time.monotonic() - t0 < 30.0:
            time.sleep(0.05)
        time.sleep(max(0.0, 1.2 - (time.monotonic() - t0)))
        state["moving"] = True
        t1 = time.monotonic()
        while probe.stalls[0].duration_s is None and time.monotonic() - t1 < 30.0:
            time.sleep(0.05)
    assert len(probe.stalls) == 1, probe.summary()
    s = probe.stalls[0]
    assert s.report is not None and s.report.exists()
    text = s.report.read_text()
    assert "progress stood still at" in text and "me[" in text
    assert "== Python stacks of me" in text
    assert "progress moved again after" in text
    assert s.duration_s is not None and 1.0 < s.duration_s < 30.0, s.duration_s
    assert "stall at progress" in probe.summary()


def test_no_stall_while_the_progress_moves(tmp_path):
    p = {"v": 0.0}

    def progress() -> float:
        p["v"] += 1.0
        return p["v"]

    with StallProbe(progress, {}, tmp_path, stall_s=0.2, period_s=0.02) as probe:
        time.sleep(0.5)
    assert probe.stalls == [] and probe.summary() == "stall probe: no stall"
    assert list(tmp_path.iterdir()) == []
