"""StepParts books wall and thread-CPU time to the part that was lapped: a sleep is wall time
without CPU, a busy loop is CPU (checked against the thread clock read independently)."""

from __future__ import annotations

import time

from vtolftc.telemetry.step_parts import StepParts


def test_sleep_is_wall_time_and_a_busy_loop_is_cpu_time():
    p = StepParts(("wait", "work", "idle"))
    p.start()
    time.sleep(0.05)
    p.lap("wait")
    c0 = time.thread_time()
    while time.thread_time() - c0 < 0.03:  # 30 ms of this thread's CPU, whatever the load
        pass
    p.lap("work")
    assert p.wall["wait"] >= 0.05 and p.cpu["wait"] < 0.01
    assert p.cpu["work"] >= 0.03 and p.wall["work"] >= p.cpu["work"]
    assert p.wall["idle"] == p.cpu["idle"] == 0.0
    s = p.summary(2)
    assert list(s["part_mean_us"]) == ["wait", "work", "idle"]
    assert s["part_mean_us"]["wait"] == 1e6 * p.wall["wait"] / 2
    assert s["part_cpu_mean_us"]["work"] == 1e6 * p.cpu["work"] / 2


def test_start_books_nothing_and_laps_chain():
    p = StepParts(("a", "b"))
    p.start()
    time.sleep(0.02)
    t0, _ = p.start()  # the sleep before it is booked nowhere
    t1, _ = p.lap("a")
    time.sleep(0.02)
    t2, _ = p.lap("b")
    assert p.wall["a"] == t1 - t0 < 0.02 <= p.wall["b"] == t2 - t1
