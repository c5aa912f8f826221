"""The compiled metrics kernel against its Python reference and the accumulator's old algebra.

``metrics_step`` (numba) must give the very bits of ``metrics_step_py`` on random samples,
through every branch (window or not, crash, quad-chute, yaw wrap, ring growth); the
accumulator built on it must equal a direct Python restatement of the metrics.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.interface import FlightMode, NavState
from vtolftc.telemetry import metrics_kernel as mk
from vtolftc.telemetry.metrics import MetricsAccumulator


def _random_samples(rng: np.random.Generator, n: int, dt_us: int) -> list[tuple]:
    out = []
    for k in range(n):
        t = k * dt_us + int(rng.integers(0, 3))
        pos = np.array([rng.normal(), rng.normal(), -abs(rng.normal(10.0, 8.0))])
        if rng.random() < 0.01:
            pos[2] = math.nan
        att = rng.normal(0.0, 0.6, 3)
        att[2] = rng.uniform(-math.pi, math.pi)
        ref = rng.normal(0.0, 0.3, 3)
        ref[2] = rng.uniform(-math.pi, math.pi)
        if rng.random() < 0.02:  # wrap exactly at the edges
            ref[2], att[2] = math.pi, -math.pi
        mode = int(rng.integers(0, 7))
        out.append((t, pos, float(att[0]), float(att[1]), float(att[2]), mode,
                    bool(rng.random() < 0.8), ref, float(rng.normal(20.0, 10.0)),
                    float(rng.uniform(0.0, 20.0))))
    return out


def _same_bits(a: np.ndarray, b: np.ndarray) -> None:
    """Equal to the last bit, except the sign of a NaN (numba's negation of a NaN may keep
    its sign; no metric shows it: a NaN prints as nan either way)."""
    na, nb = np.isnan(a), np.isnan(b)
    assert (na == nb).all()
    assert a[~na].tobytes() == b[~nb].tobytes()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_equals_python_reference_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    samples = _random_samples(rng, 3000, 4000 + 3000 * seed)  # 250 Hz and slower
    s_py, s_nb = mk.new_state(1.5), mk.new_state(1.5)
    t_py, t_nb = np.zeros((64, 4)), np.zeros((64, 4))
    grew = 0
    for smp in samples:
        a = mk.metrics_step_py(s_py, t_py, *smp)
        b = mk.metrics_step(s_nb, t_nb, *smp)
        assert a == b
        if not a:  # ring full: grow both the same way and retry
            grew += 1
            t_py = np.concatenate((np.roll(t_py, -int(s_py[mk.S_HEAD]), axis=0),
                                   np.zeros_like(t_py)))
            t_nb = np.concatenate((np.roll(t_nb, -int(s_nb[mk.S_HEAD]), axis=0),
                                   np.zeros_like(t_nb)))
            s_py[mk.S_HEAD] = s_nb[mk.S_HEAD] = 0.0
            a = mk.metrics_step_py(s_py, t_py, *smp)
            assert a == mk.metrics_step(s_nb, t_nb, *smp)
        assert a == (2 if s_py[mk.S_CRASHED] != 0.0 else 1)  # 2: added, crashed
        _same_bits(s_py, s_nb)
        _same_bits(t_py, t_nb)
    assert grew > 0 or seed > 0  # 250 Hz overflows a 64-row ring
    assert s_py[mk.S_CRASHED] == 1.0 and s_py[mk.S_N] == len(samples)


def _old_metrics(samples: list[tuple], window: float) -> dict[str, object]:
    """The accumulator's algebra restated in plain Python (before the kernel)."""
    se = [0.0] * 4
    mx = [0.0] * 3
    tilt = lost = 0.0
    n_win = 0
    tail: list[tuple[float, float, float, float]] = []
    r2d = math.degrees(1.0)
    last = None
    for t_us, pos, roll, pitch, yaw, _mode, _armed, ref, alt_ref, air in samples:
        t = t_us * 1e-6
        h = -float(pos[2])
        e_h = alt_ref - h
        if t >= window:
            e0 = (ref[0] - roll) * r2d
            e1 = (ref[1] - pitch) * r2d
            e2 = -((-((ref[2] - yaw) * r2d) + 180.0) % 360.0 - 180.0)
            n_win += 1
            for i, e in enumerate((e_h, e0, e1, e2)):
                se[i] += e * e
            for i, e in enumerate((e0, e1, e2)):
                mx[i] = max(mx[i], abs(e))
            tilt = max(tilt, abs(roll) if abs(roll) > abs(pitch) else abs(pitch))
            lost = max(lost, e_h)
        last = (h, e_h, air)
        tail.append((t, roll * r2d, pitch * r2d, yaw * r2d))
        while t - tail[0][0] > 1.0 + 1e-9:
            tail.pop(0)
    return {"rmse": [math.sqrt(x / n_win) for x in se], "max": mx, "tilt": tilt * r2d,
            "lost": lost, "last": last,
            "final": [sum(r[i] for r in tail) / len(tail) for i in (1, 2, 3)]}


def test_accumulator_equals_plain_python_and_grows_its_ring() -> None:
    rng = np.random.default_rng(7)
    samples = _random_samples(rng, 2500, 1000)  # 1 kHz: the 512-row ring must grow
    for smp in samples:  # no crash in this one: finite positions
        smp[1][2] = -abs(smp[1][2]) if math.isfinite(smp[1][2]) else -5.0
    acc = MetricsAccumulator(window_start_s=0.5)
    for t, pos, roll, pitch, yaw, mode, armed, ref, alt_ref, air in samples:
        nav = NavState(t, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), pos, np.zeros(3), air)
        acc.add_step(t, nav, FlightMode(mode), armed, ref, alt_ref, (roll, pitch, yaw))
    m = acc.result()
    ref_m = _old_metrics(samples, 0.5)
    assert acc._tail.shape[0] > 512
    assert [m["rmse_altitude_m"], m["rmse_roll_deg"], m["rmse_pitch_deg"],
            m["rmse_yaw_deg"]] == ref_m["rmse"]
    assert [m["max_abs_roll_error_deg"], m["max_abs_pitch_error_deg"],
            m["max_abs_yaw_error_deg"]] == ref_m["max"]
    assert m["max_attitude_excursion_deg"] == ref_m["tilt"]
    assert m["max_altitude_lost_m"] == ref_m["lost"]
    assert (m["final_altitude_m"], m["final_altitude_error_m"],
            m["final_airspeed_m_s"]) == ref_m["last"]
    assert [m["final_roll_deg"], m["final_pitch_deg"], m["final_yaw_deg"]] == ref_m["final"]
    assert m["samples"] == len(samples)
    # plain Python types (run.json / metrics.json are written with the json module)
    assert type(m["crashed"]) is bool and type(m["quad_chute"]) is bool
    assert type(m["samples"]) is int and type(m["rmse_roll_deg"]) is float


def test_add_step_returns_crashed_after_each_sample() -> None:
    """``add_step``'s return (the kernel's 2) is :attr:`crashed` after every sample, before
    and after the crash."""
    rng = np.random.default_rng(0)
    acc = MetricsAccumulator(window_start_s=1.5)
    seen = set()
    for t, pos, roll, pitch, yaw, mode, armed, ref, alt_ref, air in _random_samples(rng, 3000,
                                                                                  4000):
        nav = NavState(t, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), pos, np.zeros(3), air)
        got = acc.add_step(t, nav, FlightMode(mode), armed, ref, alt_ref, (roll, pitch, yaw))
        assert got is acc.crashed
        seen.add(got)
    assert seen == {False, True}
