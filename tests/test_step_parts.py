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


def test_trace_keeps_one_row_per_step_with_each_parts_wall_cpu_and_end_time():
    """Rows against the lap times read independently: each part's own wall and CPU time in
    its step (not the running sums), its last lap's time, NaN for a part not lapped in that
    step, the key, and the thread's cumulative switches / faults (never decreasing)."""
    import math

    p = StepParts(("wait", "work"))
    p.enable_trace(10)
    laps = []
    p.start()
    for step in range(3):
        time.sleep(0.002)
        t_wait, _ = p.lap("wait")
        time.sleep(0.001)  # two laps of one part in a step: summed, the last end kept
        t_wait2, c_wait2 = p.lap("wait")
        if step != 1:  # step 1 has no "work" part
            c0 = time.thread_time()
            while time.thread_time() - c0 < 0.002:
                pass
            t_work, c_work = p.end_step("work", 4000.0 * step)
        else:
            t_work, c_work = p.end_step("wait", 4000.0 * step)
        laps.append((t_wait, t_wait2, t_work, c_wait2, c_work))
    tr = p.trace()
    assert set(tr) == {"wall_wait", "wall_work", "cpu_wait", "cpu_work", "end_wait",
                       "end_work", "key", "nivcsw", "nvcsw", "minflt", "majflt"}
    assert list(tr["key"]) == [0.0, 4000.0, 8000.0]
    t_prev = None
    for i, (_t_wait, t_wait2, t_work, c_wait2, c_work) in enumerate(laps):
        if i == 1:
            assert tr["end_wait"][i] == t_work and math.isnan(tr["end_work"][i])
            assert tr["wall_work"][i] == tr["cpu_work"][i] == 0.0
            assert tr["wall_wait"][i] == t_work - laps[0][2]
        else:
            assert tr["end_wait"][i] == t_wait2 and tr["end_work"][i] == t_work
            assert tr["wall_work"][i] == t_work - t_wait2
            assert tr["cpu_work"][i] == c_work - c_wait2 >= 0.002
            if t_prev is not None:
                assert abs(tr["wall_wait"][i] - (t_wait2 - t_prev)) < 1e-12
        assert tr["wall_wait"][i] >= 0.003 > tr["cpu_wait"][i]
        t_prev = t_work
    for k in ("wall", "cpu"):  # every lap of the steps in its row, nothing twice
        for part in ("wait", "work"):
            assert abs(tr[f"{k}_{part}"].sum() - getattr(p, k)[part]) < 1e-12, (k, part)
    for c in ("nivcsw", "nvcsw", "minflt", "majflt"):
        assert (tr[c] >= 0).all() and (tr[c][1:] >= tr[c][:-1]).all()
    assert tr["nvcsw"][-1] > tr["nvcsw"][0]  # the sleeps are voluntary switches


def test_trace_is_off_by_default_and_stops_when_full(tmp_path):
    import numpy as np

    p = StepParts(("a",))
    p.start()
    p.end_step("a", 1.0)
    assert len(p.trace()["key"]) == 0
    p.save_trace(tmp_path / "none.npz")
    assert not (tmp_path / "none.npz").exists()
    p.enable_trace(2)
    for k in range(5):
        p.end_step("a", float(k))
    assert list(p.trace()["key"]) == [0.0, 1.0]
    assert p.wall["a"] > 0.0 and p._cur is None  # the sums go on; the trace stopped
    p.save_trace(tmp_path / "t.npz")
    assert list(np.load(tmp_path / "t.npz")["key"]) == [0.0, 1.0]
