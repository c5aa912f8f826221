"""The in-process runner's fused tail of a control step (:mod:`vtolftc.runners.inproc_kernel`)
against the separate calls it replaces, equal to the last bit: the kernel on random and
adversarial inputs (non-finite commands, a full metrics tail ring, a state the HIL codec
refuses), and whole flights with and without the fusion."""

from __future__ import annotations

import copy
import hashlib

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.interface import FlightMode
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.protocols.hil import HilRoundTrip, NavState
from vtolftc.runners import scenario as runner
from vtolftc.runners.inproc_kernel import runner_tail_step
from vtolftc.telemetry import metrics_kernel as mk
from vtolftc.telemetry.metrics import MetricsAccumulator

HOME = (47.397742, 8.545594, 488.0)


def _nav_bits(nav: NavState) -> bytes:
    return b"".join(np.ascontiguousarray(a).tobytes() for a in
                    (nav.q_wxyz, nav.omega_body_rad_s, nav.pos_ned_m, nav.vel_ned_m_s)) \
        + np.float64(nav.airspeed_m_s).tobytes() + int(nav.time_usec).to_bytes(8, "little")


def _fused(veh, acc, rt, t, pos, euler, mode, armed, ref, alt_ref, air, u):
    a = np.full(14, 7.0)
    args = veh.control_step_args(u)
    s, tail = acc.kernel_arrays
    r = runner_tail_step(s, tail, t, pos, *euler, mode, armed, ref, alt_ref, air, u,
                         args[0], args[1], 4, args[2], args[3], args[4], args[5],
                         rt.kernel_home, a)
    return r, a


def test_tail_step_equals_the_separate_calls_bit_for_bit(ds1):
    """Metrics sample, ``Vehicle.step(u, 4, wire=True)`` and ``HilRoundTrip`` of the state it
    leaves, on random commands and samples (crash tilts among them), through a fault, equal to
    the last bit; the answer is the metrics' (2 once crashed)."""
    from vtolftc.firmware_sim.vehicle.faults import case_faults

    rng = np.random.default_rng(16)
    fast, ref_v = Vehicle(ds1), Vehicle(ds1)
    acc_f, acc_r = MetricsAccumulator(0.5), MetricsAccumulator(0.5)
    rt = HilRoundTrip(*HOME)
    fault = case_faults("1", ds1.actuator_names)[0]
    u_min = np.r_[np.zeros(10), -np.ones(5)]
    seen = set()
    for k in range(300):
        if k == 120:
            fast.inject(fault)
            ref_v.inject(fault)
        u = rng.uniform(u_min, 1.0)  # not float32-exact: the wire rounding matters
        t = fast.time_usec
        pos = rng.normal(0.0, 20.0, 3)
        tilt = 1.2 if k in (200, 201) else 0.3
        euler = tuple(rng.uniform(-tilt, tilt, 3).tolist())
        mode = int(rng.choice([int(m) for m in FlightMode]))
        armed = bool(rng.random() < 0.9)
        att_ref = rng.normal(0.0, 0.3, 3)
        alt_ref, air = float(rng.uniform(0, 60)), float(rng.uniform(0, 30))
        sample = NavState(t, np.zeros(4), np.zeros(3), pos, np.zeros(3), air)
        if fast.control_step_args(u) is None:  # a fault pending: the runner flies step()
            r = 2 if acc_f.add_step(t, sample, mode, armed, att_ref, alt_ref, euler) else 1
            fast.step(u, 4, wire=True)
            a = None
        else:
            r, a = _fused(fast, acc_f, rt, t, pos, euler, mode, armed, att_ref, alt_ref, air,
                          u)
            fast.time_usec += 4 * fast.dt_usec
        crashed_r = acc_r.add_step(t, sample, mode, armed, att_ref, alt_ref, euler)
        ref_v.step(u, 4, wire=True)
        seen.add(r)
        assert r == (2 if crashed_r else 1), k
        assert fast.time_usec == ref_v.time_usec
        assert fast._vws.tobytes() == ref_v._vws.tobytes(), k
        for x, y in zip(acc_f.kernel_arrays, acc_r.kernel_arrays, strict=True):
            assert x.tobytes() == y.tobytes(), k
        if a is not None:
            nav = rt(ref_v.time_usec, ref_v.x, float(ref_v.fm[6]))
            mine = runner.nav_of_round_trip(ref_v.time_usec, a, a.item(13))
            assert _nav_bits(mine) == _nav_bits(nav), k
    assert seen == {1, 2}


def test_tail_step_adversarial_answers(ds1):
    """Non-finite commands: the metrics' answer + 4, the vehicle and ``nav_next`` untouched
    (``Vehicle.step`` then raises its error); a full tail ring: 0 and nothing changed; a state
    the HIL codec refuses: airspeed -1 in ``nav_next[13]`` where ``HilRoundTrip`` raises."""
    veh, acc, rt = Vehicle(ds1), MetricsAccumulator(0.0), HilRoundTrip(*HOME)
    u = np.full(15, 0.3)
    assert veh.control_step_args(u) is None  # before the first step: nothing packed yet
    veh.step(u, 4, wire=True)
    bad = u.copy()
    bad[4] = np.inf
    ws0, s0 = veh._vws.copy(), acc.kernel_arrays[0].copy()
    r, a = _fused(veh, acc, rt, 0, np.zeros(3), (0.0, 0.0, 0.0), 2, True, np.zeros(3), 1.0,
                  0.0, bad)
    assert r == 5 and veh._vws.tobytes() == ws0.tobytes() and np.all(a == 7.0)
    assert acc.kernel_arrays[0].tobytes() != s0.tobytes()  # the sample was added
    with pytest.raises(ValueError, match="NaN or inf"):
        veh.step(bad, 4, wire=True)
    # the tail ring full: nothing done
    full = copy.deepcopy(acc)
    full.kernel_arrays[0][mk.S_LEN] = full.kernel_arrays[1].shape[0]  # as many as it holds
    s_before, ws0 = full.kernel_arrays[0].copy(), veh._vws.copy()
    r, a = _fused(veh, full, rt, 4000, np.zeros(3), (0.0, 0.0, 0.0), 2, True, np.zeros(3),
                  1.0, 0.0, u)
    assert r == 0 and veh._vws.tobytes() == ws0.tobytes() and np.all(a == 7.0)
    assert full.kernel_arrays[0].tobytes() == s_before.tobytes()
    # a state the codec refuses (a non-finite attitude after the step)
    veh.x[6:10] = np.nan
    r, a = _fused(veh, acc, rt, 8000, np.zeros(3), (0.0, 0.0, 0.0), 2, True, np.zeros(3),
                  1.0, 0.0, u)
    assert r in (1, 2) and a[13] == -1.0
    with pytest.raises(ValueError):
        rt(veh.time_usec, veh.x, float(veh.fm[6]))


def _flight(monkeypatch, fused: bool, case: str, duration: float, control_hz: int = 250):
    calls = []
    if not fused:
        monkeypatch.setattr(Vehicle, "control_step_args", lambda self, c: None)
    else:
        real = runner.runner_tail_step

        def counted(*a):
            calls.append(1)
            return real(*a)

        monkeypatch.setattr(runner, "runner_tail_step", counted)
    h = hashlib.sha256()

    def setup(ap):
        step = ap.step

        def rec(nav):
            u = step(nav)
            h.update(u.tobytes())
            h.update(_nav_bits(nav))
            return u

        ap.step = rec

    res = runner.run_scenario(runner.paper_scenario(case, duration), "gs-shif",
                              autopilot_setup=setup, control_hz=control_hz)
    monkeypatch.undo()
    m = {k: repr(v) for k, v in res.metrics.items() if k != "allocation"}
    return h.hexdigest(), m, res.sim_time_s, [e[1:] for e in res.events], len(calls)


@pytest.mark.parametrize(("case", "duration", "hz"), [("1", 26.0, 250), ("0", 3.0, 1000)])
def test_flights_with_and_without_the_fused_call_are_bit_identical(monkeypatch, case,
                                                                   duration, hz):
    """Whole flights: every step's commands and navigation state, the metrics, the events and
    the end time equal with the fused call and with the separate calls. Case 1 to 26 s
    (take-off, transition, its fault at 22 s: the pending-fault steps fly ``Vehicle.step``);
    at 1 kHz the metrics' tail ring fills (the kernel's 0, then ``add_step`` grows it)."""
    sep = _flight(monkeypatch, False, case, duration, hz)
    fus = _flight(monkeypatch, True, case, duration, hz)
    assert sep[4] == 0 and fus[4] > 0.9 * duration * hz
    assert fus[:4] == sep[:4]


def test_fused_runner_never_overwrites_the_nav_the_autopilot_holds():
    """The fused call decodes the next state into two buffers in turn (session 17): each
    step's ``NavState`` is a new object, and the previous step's (the estimate's
    ``last_nav``, read by commands handled before the next step, e.g. loiter and RTL) keeps
    its values until the autopilot has flown on the next one; the buffers are reused (no
    array per step)."""
    seen: list[tuple[NavState, bytes]] = []
    ids: set[int] = set()
    bases: list[int] = []

    def setup(ap):
        step = ap.step

        def rec(nav):
            if seen:  # the last step's nav, as the autopilot's estimate holds it
                prev, bits = seen[-1]
                assert ap.estimate.last_nav is prev
                assert _nav_bits(prev) == bits, len(seen)
                assert nav is not prev
            u = step(nav)
            assert ap.estimate.last_nav is nav
            seen.append((nav, _nav_bits(nav)))
            ids.add(id(nav))
            bases.append(id(nav.pos_ned_m.base))
            return u

        ap.step = rec

    runner.run_scenario(runner.paper_scenario("1", 6.0), "gs-shif", autopilot_setup=setup)
    assert len(seen) == 1500
    assert len(ids) > 2  # fresh objects (ids of dead ones may be reused, not 2)
    # the steps not fused (the first, the vehicle's pending steps) decode into new arrays;
    # the others into the two buffers
    counts = sorted((bases.count(b) for b in set(bases)), reverse=True)
    assert counts[0] + counts[1] > 0.95 * len(seen), counts[:4]
