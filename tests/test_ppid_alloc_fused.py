"""The attitude stage's P-PID step fused into the allocation's compiled call (issue 24, session
17: ``ActiveSetAllocator.allocate_tracked(..., ppid=...)``, kernel
``active_set._ppid_allocate_step_tracked``) against the two calls it replaced
(``scheduled_ppid3_step_packed``, then ``allocate_tracked(..., v_tail=tau)``), bit for bit: on
random and adversarial inputs, on whole flights, and with a replaced allocator."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.allocation import ActiveSetAllocator
from vtolftc.firmware_sim.autopilot.attitude_stage import AttitudeStage
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.control_kernels import scheduled_ppid3_step_packed
from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel
from vtolftc.firmware_sim.autopilot.interface import FlightMode, NavState


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype=np.float64).tobytes()


@pytest.mark.parametrize("controller", ["gs-shif", "shif"])
def test_fused_call_equals_ppid_then_allocate_tracked(ds1, controller):
    """Two identical autopilots' controller and allocator, fed the same random problems: one
    through ``allocate_tracked(..., ppid=...)``, the other through the P-PID kernel and then
    ``allocate_tracked(..., v_tail=<its output>)``: the same status, mask, ``(B u)[0]``,
    ``v``, command, P-PID workspace (gains, state, output), allocator workspace and
    statistics, step after step. Adversarial steps: airspeeds off the schedule's ends and
    on its breakpoints, every saturation flag, huge errors (saturated moments, infeasible
    demands), signed zeros, a NaN rate (the P-PID's NaN moments: the allocation's
    invalid-input path), an infinite attitude error, stale NaN in ``v``'s tail."""
    one, two = Autopilot(ds1, controller=controller), Autopilot(ds1, controller=controller)
    c1, c2 = one.attitude_stage.controller, two.attitude_stage.controller
    a1: ActiveSetAllocator = one.output.allocator
    a2: ActiveSetAllocator = two.output.allocator
    bp = c1.schedule.kernel_packed[: (c1.schedule.kernel_packed.size + 15) // 31]
    eff = EffectivenessModel(ds1)
    rng = np.random.default_rng(1703)
    n_u = a1.n_u
    u1, u2 = np.empty(n_u), np.empty(n_u)
    statuses, masks = set(), set()
    for k in range(600):
        V = float(rng.choice([0.0, 3.0, 7.3, 12.0, 17.9]))
        B = eff.matrix_on_grid(V, 0.1)
        vs = float(rng.choice([V + rng.normal(0.0, 0.5), -2.0, 40.0,
                               float(rng.choice(bp)), -0.0]))
        ref = rng.normal(0.0, 0.3, 3)
        att = rng.normal(0.0, 0.3, 3)
        att[2] = rng.uniform(-np.pi, np.pi)
        rates = rng.normal(0.0, 0.5, 3)
        scale = float(rng.choice([1.0, 1.0, 1.0, 30.0]))
        ref *= scale
        if k % 97 == 13:
            rates[int(rng.integers(3))] = np.nan
        if k % 89 == 40:
            ref[0] = np.inf
        if k % 53 == 7:
            ref[:], att[:], rates[:] = 0.0, -0.0, -0.0
        sat_mask = int(rng.integers(64)) if k % 3 else 0
        v = np.array([-ds1.weight_N, 5.0, 0.0, 0.0, 0.0]) + rng.normal(0, 1, 5) * [
            60.0, 20.0, 15.0, 15.0, 5.0] * (4.0 if k % 11 == 5 else 1.0)
        v[2:] = np.nan if k % 5 == 0 else rng.normal(0.0, 100.0, 3)  # stale tail
        hi = np.ones(n_u)
        hi[: one.n_rotors] = float(rng.choice([1.0, 0.6]))
        pref = one.u_pref_mc if k % 2 else one.u_pref_fw
        v1, v2 = v.copy(), v.copy()
        a = a1.allocate_tracked(
            v1, B, hi, pref, u1, 2, 0.02, 0.02,
            ppid=(c1.schedule.kernel_packed, vs, ref, att, rates, c1.kernel_ws, sat_mask))
        scheduled_ppid3_step_packed(c2.schedule.kernel_packed, vs, ref, att, rates,
                                    c2.kernel_ws, sat_mask)
        b = a2.allocate_tracked(v2, B, hi, pref, u2, 2, 0.02, 0.02,
                                v_tail=c2.kernel_arrays[3])
        statuses.add(a[0])
        masks.add(a[1])
        assert np.array(a).tobytes() == np.array(b).tobytes(), k
        assert _bits(v1) == _bits(v2) and _bits(u1) == _bits(u2), k
        assert _bits(c1.kernel_ws) == _bits(c2.kernel_ws), k
        assert _bits(a1._wsx) == _bits(a2._wsx), k
    assert len(statuses) >= 2 and len(masks) >= 8  # solved, invalid input; saturated axes
    assert a1.stats.counts == a2.stats.counts
    assert a1.stats.total_iterations == a2.stats.total_iterations


def _fly_hash(monkeypatch: pytest.MonkeyPatch | None, case: str, duration: float,
              controller: str) -> tuple[str, list[tuple[FlightMode, bool]], int]:
    """Every step's commands and P-PID state of a flight, hashed; with ``monkeypatch`` the
    fused call switched off (the P-PID kernel, then ``allocate_tracked(..., v_tail=tau)``:
    the separate calls this session replaced). Also the modes flown and the number
    of fused steps."""
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    fused = [0]
    args_of = AttitudeStage.kernel_step_args

    def counted(self, *a):
        r = args_of(self, *a)
        fused[0] += r is not None
        return r

    if monkeypatch is not None:
        # the separate calls: the P-PID kernel on the stage's arguments, its output array as
        # the torques handed to the allocation (``allocate_tracked(..., v_tail=tau)``)
        real_update = AttitudeStage.controller_update

        def separate(self, *a):
            args = args_of(self, *a)
            self.test_tau = None
            if args is not None:
                scheduled_ppid3_step_packed(*args)
                self.test_tau = self.controller.kernel_arrays[3]
            return None

        def update(self, *a):
            tau = self.test_tau
            return tau if tau is not None else real_update(self, *a)

        monkeypatch.setattr(AttitudeStage, "kernel_step_args", separate)
        monkeypatch.setattr(AttitudeStage, "controller_update", update)
    else:
        AttitudeStage.kernel_step_args = counted  # type: ignore[method-assign]
    h, modes = hashlib.sha256(), []

    def setup(ap):
        step = ap.step
        ws = getattr(ap.attitude_stage.controller, "kernel_ws", np.empty(0))

        def rec(nav):
            u = step(nav)
            h.update(u.tobytes())
            h.update(ws.tobytes())
            modes.append((ap.modes.mode, ap.output._fw_reserve))
            return u

        ap.step = rec

    try:
        run_scenario(paper_scenario(case, duration), controller, autopilot_setup=setup)
    finally:
        AttitudeStage.kernel_step_args = args_of  # type: ignore[method-assign]
    return h.hexdigest(), modes, fused[0]


@pytest.mark.parametrize(("case", "duration", "controller"),
                         [("1", 32.0, "gs-shif"), ("2", 12.0, "shif"), ("1", 4.0, "lqr")])
def test_flights_with_the_fused_call_equal_the_separate_calls(monkeypatch, case, duration,
                                                                controller):
    """Whole flights (case 1 to 32 s: take-off, hover, front transition, fixed-wing with the
    lift rotors bounded and then the reserve, the faults at 22 s; case 2's start with
    ``shif``; ``lqr``, never fused): every step's commands and P-PID state equal, bit for
    bit, to the flight whose attitude stage and allocation are the separate calls."""
    now, modes, n_fused = _fly_hash(None, case, duration, controller)
    then, modes_then, _ = _fly_hash(monkeypatch, case, duration, controller)
    assert modes == modes_then
    assert now == then
    if controller == "lqr":
        assert n_fused == 0
    else:
        assert n_fused > 0.9 * len(modes)
    if duration > 30.0:
        assert (FlightMode.FIXED_WING, True) in modes


def test_a_replaced_allocator_still_gets_the_ppid_moments(ds1):
    """With the allocator's ``allocate`` replaced (a benchmark's or a test's spy) the output
    stage runs the P-PID step itself and hands the replaced call its moments: commands, the
    virtual command and the controller's state equal, step after step, to an autopilot's
    without the spy; the spy is called at every armed step."""
    from vtolftc.firmware_sim.autopilot.autopilot import CMD_COMPONENT_ARM_DISARM

    def nav(k: int, rng: np.random.Generator) -> NavState:
        q = np.array([1.0, 0.0, 0.0, 0.0]) + rng.normal(0.0, 0.05, 4)
        return NavState(4000 * (k + 1), q / np.linalg.norm(q), rng.normal(0.0, 0.3, 3),
                        np.array([0.0, 0.0, -10.0]) + rng.normal(0.0, 0.5, 3),
                        rng.normal(0.0, 0.5, 3), float(abs(rng.normal(0.0, 3.0))))

    plain, spied = Autopilot(ds1), Autopilot(ds1)
    calls = [0]
    a0 = spied.output.allocator.allocate

    def spy(*a, **kw):
        calls[0] += 1
        return a0(*a, **kw)

    spied.output.allocator.allocate = spy
    for ap in (plain, spied):
        ap.step(NavState(0, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3),
                         np.array([0.0, 0.0, -0.29]), np.zeros(3), 0.0))  # on the ground
        assert ap.command(CMD_COMPONENT_ARM_DISARM, [1.0] + [np.nan] * 6).name == "ACCEPTED"
        ap.modes.set_mode(FlightMode.HOVER, "test")
    r1, r2 = np.random.default_rng(5), np.random.default_rng(5)
    for k in range(200):
        u1, u2 = plain.step(nav(k, r1)), spied.step(nav(k, r2))
        assert _bits(u1) == _bits(u2), k
        assert _bits(plain.setpoints.v) == _bits(spied.setpoints.v), k
        assert _bits(plain.attitude_stage.controller.kernel_ws) == _bits(
            spied.attitude_stage.controller.kernel_ws), k
    assert calls[0] == 200


def test_kernel_step_args_resets_on_the_ground_and_schedules_the_airspeed(ds1):
    """``kernel_step_args`` does ``update``'s work before the controller: in TAKEOFF below
    0.5 m above the ground the controller is reset (its state as a reset twin's), above it
    and in other modes it is kept; the scheduled airspeed is the FTC_SCHED_TAU low-pass,
    written out here, and the answer the compiled step's arguments."""
    ap, twin = Autopilot(ds1), Autopilot(ds1)
    stage = ap.attitude_stage
    ctrl = stage.controller
    stage.est.ground_alt = 100.0
    rng = np.random.default_rng(8)
    rates = rng.normal(0.0, 0.5, 3)
    ref, att = rng.normal(0.0, 0.3, 3), rng.normal(0.0, 0.3, 3)
    v_sched = np.nan
    for k, (mode, h) in enumerate([(FlightMode.HOVER, 100.1), (FlightMode.TAKEOFF, 100.6),
                                   (FlightMode.TAKEOFF, 100.2), (FlightMode.HOVER, 100.1),
                                   (FlightMode.TAKEOFF, 100.49)]):
        for _ in range(5):  # some controller state
            stage.update(FlightMode.HOVER, 120.0, 5.0, ref, att, rates, [False] * 3,
                         [False] * 3)
            v_sched = 5.0 if np.isnan(v_sched) else v_sched + 0.004 / 0.5 * (5.0 - v_sched)
        before = ctrl.kernel_ws.copy()
        V = float(rng.uniform(0.0, 20.0))
        args = stage.kernel_step_args(mode, h, V, ref, att, rates, 5)
        v_sched = v_sched + 0.004 / 0.5 * (V - v_sched)
        assert stage.v_sched == v_sched, k
        assert args[1] == v_sched and args[6] == 5 and args[5] is ctrl.kernel_ws, k
        assert args[0] is ctrl.schedule.kernel_packed and args[4] is rates, k
        if mode is FlightMode.TAKEOFF and h < 100.5:
            twin.attitude_stage.controller.kernel_ws[:] = before
            twin.attitude_stage.controller.reset()
            assert _bits(ctrl.kernel_ws) == _bits(twin.attitude_stage.controller.kernel_ws)
            assert _bits(ctrl.kernel_ws) != _bits(before), k
        else:
            assert _bits(ctrl.kernel_ws) == _bits(before), k
