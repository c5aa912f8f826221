"""The per-step fast paths of the autopilot (issue 24) against the Python they replace, equal
to the last bit on random inputs: a changed operation order or a dropped branch fails here
before it changes a flight (``benchmarks/command_digest.py`` checks three whole flights)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from vtolftc.base.rotation import quat_to_euler
from vtolftc.firmware_sim.autopilot.allocation import ActiveSetAllocator, AllocationStatus
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel
from vtolftc.firmware_sim.autopilot.estimate import StateEstimate
from vtolftc.firmware_sim.autopilot.interface import FlightMode, NavState


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a, dtype=np.float64).tobytes()


def test_allocate_trusted_equals_allocate_bit_for_bit(ds1):
    """The same sequence of problems (airspeed grid points, reserve rows, rate and position
    limits, infeasible commands, a non-finite command) through ``allocate`` and
    ``allocate_trusted`` of two identical allocators: same ``u``, ``B u``, status, warm start
    and statistics, step after step."""
    ap = Autopilot(ds1)
    ref: ActiveSetAllocator = ap.output.allocator
    fast: ActiveSetAllocator = Autopilot(ds1).output.allocator
    tracked: ActiveSetAllocator = Autopilot(ds1).output.allocator
    u_out = np.empty(ref.n_u)
    eff = EffectivenessModel(ds1)
    rng = np.random.default_rng(24)
    n_u = ref.n_u
    statuses = set()
    for k in range(400):
        V = float(rng.choice([0.0, 3.0, 7.3, 12.0, 17.9]))
        B = eff.matrix_on_grid(V, 0.1)
        if k % 7 == 3:  # the output stage's reserve matrix: a writable copy, Fz row zeroed
            B = B.copy()
            B[0, :] = 0.0
        v = np.array([-ds1.weight_N, 5.0, 0.0, 0.0, 0.0]) + rng.normal(0, 1, 5) * [
            60.0, 20.0, 15.0, 15.0, 5.0] * (4.0 if k % 11 == 5 else 1.0)
        if k == 200:
            v[3] = np.nan  # INVALID_INPUT: previous command held
        hi = np.ones(n_u)
        hi[: ap.n_rotors] = float(rng.choice([1.0, 0.6, 0.0]))
        pref = ap.u_pref_mc if k % 2 else ap.u_pref_fw
        if k in (100, 300):  # a hand-over: warm start from a given command
            u0 = rng.uniform(0.0, 1.0, n_u)
            ref.reset(u0)
            fast.reset(u0)
            tracked.reset(u0)
        res = ref.allocate(v, B, u_max=hi, u_pref=pref)
        if k % 50 == 25:  # the public call in between: its own array becomes the warm start
            r2 = fast.allocate(v, B, u_max=hi, u_pref=pref)
            u, va, st = r2.u, r2.v_achieved, r2.status
        else:
            u, va, st = fast.allocate_trusted(v, B, hi, pref)
        if k % 50 == 25:
            tracked.allocate(v, B, u_max=hi, u_pref=pref)
            u_out[:] = res.u
        else:  # allocate_tracked: u into u_out, the shortfall mask of B u, (B u)[0]
            u_out.fill(np.nan)
            st_t, mask, fz = tracked.allocate_tracked(v, B, hi, pref, u_out, 2, 0.02, 0.03)
            assert st_t == res.status, k
            assert mask == _shortfall_mask_py(v, res.v_achieved, 0.02, 0.03), k
            assert np.array([fz]).tobytes() == res.v_achieved[:1].tobytes(), k
        assert _bits(u_out) == _bits(res.u), k
        assert _bits(tracked._ws) == _bits(ref._ws), k
        assert _bits(tracked._u_last) == _bits(ref._u_last), k
        statuses.add(st)
        assert st == res.status, k
        assert _bits(u) == _bits(res.u), k
        assert _bits(va) == _bits(res.v_achieved), k
        assert _bits(fast._u_last) == _bits(ref._u_last), k
        assert _bits(fast._ws) == _bits(ref._ws), k
    assert AllocationStatus.INVALID_INPUT in statuses and AllocationStatus.SOLVED in statuses
    a, b, c = ref.stats.as_dict(), fast.stats.as_dict(), tracked.stats.as_dict()
    for d in (a, b, c):
        d.pop("max_wall_time_s"), d.pop("mean_wall_time_s")
    assert a == b == c


def _shortfall_mask_py(v: np.ndarray, va: np.ndarray, atol: float, rtol: float) -> int:
    """The output stage's saturation test of the three moment axes written out in Python
    (as it was before ``shortfall_mask``): bit i short upwards, bit 3 + i downwards."""
    mask = 0
    for i, (w, g) in enumerate(zip(v[2:].tolist(), va[2:].tolist(), strict=True)):
        tol = atol + rtol * abs(w)
        mask |= (1 << i) if w > g + tol else 0
        mask |= (8 << i) if w < g - tol else 0
    return mask


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_allocator_keeps_its_workspace_views(ds1, how):
    """A deep copy or an unpickled allocator (numpy copies each array on its own) links its
    bounds, QP arrays, limits and triangle indices to its own workspace again, so it goes on
    exactly as the original: same ``u`` and workspace bits through solved, infeasible,
    invalid-input (held command, bounds from the workspace) and fallback steps."""
    import pickle

    eff = EffectivenessModel(ds1)
    orig: ActiveSetAllocator = Autopilot(ds1).output.allocator
    B = eff.matrix_on_grid(7.3, 0.1)
    v0 = np.array([-ds1.weight_N, 5.0, 0.0, 0.0, 0.0])
    for _ in range(5):
        orig.allocate(v0, B)
    twin = copy.deepcopy(orig) if how == "deepcopy" else pickle.loads(pickle.dumps(orig))
    for name in (*ActiveSetAllocator._WS_PARTS, "_tri_r", "_tri_c", "u_min", "u_max"):
        base = {"_tri_r": twin._iws, "_tri_c": twin._iws, "u_min": twin._cst,
                "u_max": twin._cst}.get(name, twin._ws)
        assert np.shares_memory(getattr(twin, name), base), name
    for name in ("_ws", "_cst", "_ubuf"):  # the tracked kernel's one float workspace
        assert np.shares_memory(getattr(twin, name), twin._wsx), name
    u_a, u_b = np.empty(orig.n_u), np.empty(orig.n_u)
    for k in range(20):  # allocate_tracked reads the limits and warm start through _wsx
        v = v0 + np.array([3.0 * k, -2.0 * k, 0.5, -0.5, 0.1])
        a = orig.allocate_tracked(v, B, orig.u_max, orig.u_pref, u_a, 2, 1e-6, 1e-3)
        b = twin.allocate_tracked(v, B, twin.u_max, twin.u_pref, u_b, 2, 1e-6, 1e-3)
        assert a == b and _bits(u_a) == _bits(u_b), k
        assert _bits(orig._wsx) == _bits(twin._wsx), k
    rng = np.random.default_rng(5)
    for k in range(60):
        v = v0 + rng.normal(0, 1, 5) * [60.0, 20.0, 15.0, 15.0, 5.0] * (6.0 if k % 9 == 4
                                                                          else 1.0)
        if k == 30:
            v[2] = np.inf
        hi = np.ones(orig.n_u)
        hi[: k % 4] = 0.0
        a = orig.allocate(v, B, u_max=hi)
        b = twin.allocate(v, B, u_max=hi)
        assert a.status == b.status, k
        assert _bits(a.u) == _bits(b.u), k
        assert _bits(orig._ws) == _bits(twin._ws), k
        assert _bits(orig._lo) == _bits(twin._lo) and _bits(orig._hi) == _bits(twin._hi), k


@pytest.mark.parametrize("path", ["tracked", "allocate"])
def test_output_stage_saturation_flags_equal_the_reference(ds1, path):
    """The output stage's saturation tracking (``allocate_tracked``'s compiled mask, or
    ``_track_saturation`` after a replaced ``allocate``) gives what the Python expressions
    give on ``v`` and ``B u`` (flags, the Fz pair, the count of saturated steps), on
    commands inside and far outside what the actuators can do; the commands are
    ``allocate``'s."""
    ap = Autopilot(ds1)
    out = ap.output
    twin = copy.deepcopy(out)  # fed the same problems through the public allocate
    if path == "allocate":  # the fast path steps aside for an allocate set on the instance
        for alloc in (out.allocator, out.allocator_fw):
            alloc.allocate = alloc.allocate
    rng = np.random.default_rng(7)
    n_sat = 0
    for k in range(300):
        V = float(rng.uniform(0.0, 20.0))
        tau = rng.normal(0, 1, 3) * [20.0, 20.0, 8.0] * (5.0 if k % 5 == 0 else 1.0)
        fz = -ds1.weight_N * float(rng.uniform(0.5, 1.6))
        fx = float(rng.uniform(0.0, 30.0))
        reserve = k % 9 == 4
        out.sp.v[0], out.sp.v[1] = fz, fx
        u = out.allocate(V, tau, reserve, 1.0, 1.0, ap.u_pref_mc)
        twin.sp.v[0], twin.sp.v[1] = fz, fx
        twin.sp.v[2:] = tau
        if reserve != twin._fw_reserve:
            (twin.allocator_fw if reserve else twin.allocator).reset(twin.u)
            twin._fw_reserve = reserve
        B = out._B if reserve else out._B_grid
        res = (twin.allocator_fw if reserve else twin.allocator).allocate(
            twin.sp.v, B, u_max=np.ones(twin.n_u), u_pref=ap.u_pref_mc)
        twin.u[:] = res.u
        assert _bits(u) == _bits(res.u) and _bits(out.u) == _bits(res.u), k
        mask = _shortfall_mask_py(twin.sp.v, res.v_achieved, 0.02, 0.02)
        assert out.sat_hi == [bool(mask & 1), bool(mask & 2), bool(mask & 4)], k
        assert out.sat_lo == [bool(mask & 8), bool(mask & 16), bool(mask & 32)], k
        assert out.sat_mask == mask, k  # the attitude stage's compiled step reads this one
        assert (out.fz_cmd, out.fz_achieved) == (fz, float(res.v_achieved[0])), k
        n_sat += mask != 0
        assert out.saturated_steps == n_sat, k
    assert 0 < out.saturated_steps < 300


def _nav(q: np.ndarray, rates: np.ndarray, t_usec: int = 4000) -> NavState:
    return NavState(t_usec, q, rates, np.array([1.0, -2.0, -30.0]), np.array([12.0, 0.5, -0.3]),
                    13.0)


def test_estimate_euler_equals_quat_to_euler(ds1):
    """``StateEstimate.update``'s inlined Euler angles are ``quat_to_euler``'s, bit for bit,
    on random attitudes and at the gimbal lock (pitch clipped at +-pi/2); a non-finite rate
    still rejects the sample."""
    est = StateEstimate()
    rng = np.random.default_rng(5)
    qs = list(rng.normal(size=(500, 4)))
    h = np.sqrt(0.5)
    qs += [np.array([h, 0.0, h, 0.0]), np.array([h, 0.0, -h, 0.0]),
           np.array([h * (1 + 1e-16), 1e-9, h, 0.0]), np.array([0.5, -0.5, 0.5, -0.5])]
    for eps in (1e-3, 1e-5, 1e-7):  # pitch just short of +-90 deg: sin(pitch) near +-1
        a = np.pi / 4 - eps
        qs += [np.array([np.cos(a), 0.0, np.sin(a), 0.0]),
               np.array([np.cos(a), 0.0, -np.sin(a), 0.0])]
    for q in qs:
        q = q / np.linalg.norm(q) if abs(np.linalg.norm(q) - 1.0) > 1e-6 else q
        got = est.update(_nav(q, rng.normal(size=3)))
        want = quat_to_euler(q)
        assert got is not None
        assert np.array([got]).tobytes() == np.array([want]).tobytes(), q
        assert est.att.tobytes() == np.array(want).tobytes()
        assert est.euler == tuple(est.att.tolist())  # what metrics_inputs hands the metrics
    kept = est.euler
    assert est.update(_nav(qs[0], np.array([0.0, np.inf, 0.0]))) is None
    assert est.euler is kept  # a rejected sample changes nothing


def test_metrics_inputs_euler_is_the_estimates_angles(ds1):
    """``Autopilot.metrics_inputs`` hands the metrics the Euler angles of the step that flew
    on ``nav`` (``tuple(est.att.tolist())``, as before), None for another ``nav``."""
    ap = Autopilot(ds1)
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = rng.normal(size=4)
        nav = _nav(q / np.linalg.norm(q), rng.normal(size=3))
        ap.step(nav)
        euler = ap.metrics_inputs(nav)[4]
        assert euler == tuple(ap.estimate.att.tolist())
        assert np.array(euler).tobytes() == np.array(quat_to_euler(nav.q_wxyz)).tobytes()
        assert ap.metrics_inputs(_nav(q, np.zeros(3)))[4] is None


@pytest.mark.parametrize("controller", ["gs-shif", "shif"])
def test_attitude_stage_direct_kernel_equals_controller_update(ds1, controller):
    """The attitude stage's direct call of the compiled scheduled step gives, step after
    step, the moments and controller state that ``ScheduledPPIDController.update`` gives
    (two controllers fed the same random references, attitudes, rates, airspeeds and
    saturation flags)."""
    fast = Autopilot(ds1, controller=controller).attitude_stage
    ref_ctrl = Autopilot(ds1, controller=controller).attitude_stage.controller
    rng = np.random.default_rng(11)
    v_sched = np.nan
    for k in range(300):
        V = float(rng.uniform(-1.0, 22.0))
        ref = rng.normal(0, 0.3, 3)
        att = rng.normal(0, 0.3, 3)
        att[2] = rng.uniform(-np.pi, np.pi)
        rates = rng.normal(0, 0.5, 3)
        sat_hi = [bool(b) for b in rng.random(3) < 0.2]
        sat_lo = [bool(b) for b in rng.random(3) < 0.2]
        mask = sum(b << i for i, b in enumerate(sat_hi + sat_lo))
        tau = fast.update(FlightMode.HOVER, 30.0, V, ref, att, rates, sat_hi, sat_lo,
                          None if k % 2 else mask).copy()
        tc = 0.5  # FTC_SCHED_TAU: the stage's low-pass, written out
        v_sched = V if k == 0 else v_sched + min(1.0, 0.004 / tc) * (V - v_sched)
        want = ref_ctrl.update(ref, att, rates, v_sched, sat_hi, sat_lo)
        assert fast.v_sched == v_sched
        assert tau.tobytes() == want.tobytes(), k
        assert fast.controller.kernel_arrays[1].tobytes() == ref_ctrl.kernel_arrays[1].tobytes()


def test_arming_check_skipped_in_flight_changes_nothing():
    """The commander skips ``ArmingMonitor.check`` while ``airborne`` and still armed out of
    IDLE: a monitor checked every step and one skipped that way end every step in the same
    state and say the same thing, on random arm / disarm / mode sequences (takeoffs,
    landings, re-arming, both disarm timers)."""
    from vtolftc.firmware_sim.autopilot.arming import ArmingMonitor
    from vtolftc.firmware_sim.autopilot.parameters import default_parameters

    ref, fast = ArmingMonitor(default_parameters()), ArmingMonitor(default_parameters())
    rng = np.random.default_rng(3)
    modes = [FlightMode.IDLE, FlightMode.TAKEOFF, FlightMode.HOVER, FlightMode.FIXED_WING]
    armed, mode, skipped = False, FlightMode.IDLE, 0
    for k in range(4000):
        t = 4000 * k
        r = rng.random()
        if r < 0.01:
            armed = not armed
        elif r < 0.03:
            mode = modes[int(rng.integers(len(modes)))]
        want = ref.check(t, armed, mode)
        if armed and fast.armed and fast.airborne and mode != FlightMode.IDLE:
            got = ""
            skipped += 1
        else:
            got = fast.check(t, armed, mode)
        assert got == want, k
        assert vars(fast) == vars(ref), k
    assert 500 < skipped < 3500


def test_metrics_add_step_returns_crashed():
    """``MetricsAccumulator.add_step`` returns ``crashed`` (the in-process runner stops on
    it): False in level flight, True from the first sample tilted past the crash limit on."""
    from vtolftc.telemetry.metrics import MetricsAccumulator

    acc = MetricsAccumulator(window_start_s=0.0)
    nav = NavState(0, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), np.array([0.0, 0.0, -30.0]),
                   np.zeros(3), 0.0)
    seen = []
    for k in range(20):
        roll = 1.5 if k >= 12 else 0.0  # 86 deg: past the 60 deg crash limit
        got = acc.add_step(4000 * k, nav, FlightMode.HOVER, True, np.zeros(3), 30.0,
                           (roll, 0.0, 0.0))
        assert got is acc.crashed
        seen.append(got)
    assert seen == [False] * 12 + [True] * 8


def test_vehicle_step_one_kernel_equals_take_commands_and_step_n_flat(ds1):
    """``Vehicle.step``'s fused call (``_take_and_step``) flies what its two kernels flew
    one after the other, bit for bit, over random commands, through a fault injection (the
    pending-fault path) and on; a non-finite command raises and changes nothing."""
    from vtolftc.firmware_sim.vehicle import dynamics as dyn
    from vtolftc.firmware_sim.vehicle import model as vm
    from vtolftc.firmware_sim.vehicle.faults import case_faults

    fast, ref = vm.Vehicle(ds1), vm.Vehicle(ds1)
    fault = case_faults("1", ds1.actuator_names)[0]
    rng = np.random.default_rng(2)
    u_min = np.r_[np.zeros(10), -np.ones(5)]
    for k in range(400):
        cmds = rng.uniform(u_min, 1.0).astype(np.float32).astype(np.float64)
        if k == 150:
            fast.inject(fault)
            ref.inject(fault)
        fast.step(cmds, 4)
        if ref._pending or ref._packed_args[0] is not ref.packed:
            ref.step(cmds, 4)  # (the same branch in both: nothing fused there)
        else:  # the two kernels the fused call replaces, as Vehicle.step called them
            assert vm._take_commands(cmds, ref.u)
            pa = ref._packed_args
            dyn.step_n_flat(ref.x, ref.u, ref.eff, ref.stuck, 4, ref.dt_usec * 1e-6, pa[1],
                            pa[2], ref.wind, ref.physics, ref.fm)
            ref.time_usec += 4 * ref.dt_usec
        assert fast.time_usec == ref.time_usec
        for name in ("x", "u", "eff", "stuck", "fm"):
            assert getattr(fast, name).tobytes() == getattr(ref, name).tobytes(), (k, name)
    x0 = fast.x.copy()
    bad = cmds.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        fast.step(bad, 4)
    assert fast.x.tobytes() == x0.tobytes() and fast.u.tobytes() == ref.u.tobytes()


def test_a_replaced_allocate_or_update_is_still_the_one_called(ds1):
    """The fast paths step aside for an ``allocate`` or ``update`` replaced on the instance
    (a benchmark's or a test's spy): the output stage and the attitude stage call them."""
    from vtolftc.firmware_sim.autopilot.autopilot import CMD_COMPONENT_ARM_DISARM

    def nav(t_s: float, alt: float) -> NavState:
        return NavState(round(t_s * 1e6), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3),
                        np.array([0.0, 0.0, -alt]), np.zeros(3), 0.0)

    ap = Autopilot(ds1)
    calls: list[str] = []
    alloc, ctrl = ap.allocator, ap.attitude
    a0, u0 = alloc.allocate, ctrl.update

    def spy_allocate(*a, **kw):
        calls.append("allocate")
        return a0(*a, **kw)

    def spy_update(*a, **kw):
        calls.append("update")
        return u0(*a, **kw)

    alloc.allocate = spy_allocate
    ctrl.update = spy_update
    ap.step(nav(0.0, 0.29))
    assert ap.command(CMD_COMPONENT_ARM_DISARM, [1.0] + [np.nan] * 6).name == "ACCEPTED"
    ap.modes.set_mode(FlightMode.HOVER, "test")
    ap.step(nav(0.004, 10.0))
    assert calls == ["update", "allocate"]


def test_derivatives_rotation_entries_against_numpy(ds1):
    """The vehicle's derivatives with the rotation as nine scalars
    (``quat_to_dcm_entries``, no array) against numpy and ``base.rotation.dcm`` on random
    states with wind: the air-relative velocity in body axes (airspeed, alpha, beta), the
    translational acceleration ``R F / m + g``, and the landing gear's contact forces and
    moments (gravity, aerodynamics and propulsion off, gear points below the ground):
    an entry of R read at the wrong place fails here."""
    from vtolftc.base.rotation import dcm
    from vtolftc.firmware_sim.vehicle import dynamics as dyn
    from vtolftc.firmware_sim.vehicle.model import Vehicle

    rng = np.random.default_rng(12)
    veh = Vehicle(ds1, wind_ned_m_s=(3.0, -2.0, 0.5))
    pk = veh.packed
    P = pk.P
    n_x = veh.x.size
    contacts = 0
    for k in range(300):
        x = np.zeros(n_x)
        x[0:3] = rng.normal(0.0, 5.0, 3)
        x[3:6] = rng.normal(0.0, 8.0, 3)
        q = rng.normal(0.0, 1.0, 4)
        q = 0.1 * q + np.array([1.0, 0.0, 0.0, 0.0]) if k % 2 else q
        x[6:10] = q / np.linalg.norm(q)
        x[10:13] = rng.normal(0.0, 1.0, 3)
        x[dyn.N_RIGID:] = rng.uniform(0.0, 1.0, n_x - dyn.N_RIGID)
        ground = k % 3 == 0
        if ground:
            x[2] = 0.5  # below the ground: the gear points that reach it in contact
            veh.physics = dyn.GROUND
        else:
            veh.physics = dyn.ALL_PHYSICS
        dx, fm = veh.derivatives(x, np.zeros(n_x - dyn.N_RIGID))
        R = dcm(x[6:10])
        vb = R.T @ (x[3:6] - veh.wind)
        Va = float(np.linalg.norm(vb))
        assert fm[6] == pytest.approx(Va, rel=1e-12)
        assert fm[7] == pytest.approx(np.arctan2(vb[2], vb[0]), abs=1e-12)
        assert fm[8] == pytest.approx(np.arcsin(vb[1] / Va), abs=1e-12)
        g = P[dyn.P_G] if veh.physics & dyn.GRAVITY else 0.0
        np.testing.assert_allclose(dx[3:6], R @ fm[0:3] / P[dyn.P_MASS] + [0.0, 0.0, g],
                                   rtol=1e-11, atol=1e-9)
        np.testing.assert_array_equal(dx[0:3], x[3:6])
        if ground:
            w = x[10:13]
            F = np.zeros(3)
            Mo = np.zeros(3)
            for r in pk.gear:
                pz = x[2] + (R @ r)[2]
                if pz <= 0.0:
                    continue
                contacts += 1
                pv = x[3:6] + R @ np.cross(w, r)
                normal = max(0.0, P[dyn.P_GK] * pz + P[dyn.P_GC] * pv[2])
                fh = -P[dyn.P_GF] * pv[0:2]
                nh = float(np.linalg.norm(fh))
                if nh > P[dyn.P_GMU] * normal and nh > 0.0:
                    fh *= P[dyn.P_GMU] * normal / nh
                fb = R.T @ np.array([fh[0], fh[1], -normal])
                F += fb
                Mo += np.cross(r, fb)
            np.testing.assert_allclose(fm[0:3], F, rtol=1e-11, atol=1e-8)
            np.testing.assert_allclose(fm[3:6], Mo, rtol=1e-11, atol=1e-8)
    assert contacts > 200


def test_vehicle_step_memo_equals_full_evaluation_bit_for_bit(ds1):
    """The fused control step reusing the last step's final derivative evaluation
    (``dynamics.step_n_memo``) flies what ``step_n_flat`` (every stage evaluated) flies, bit
    for bit, over random commands, with the effectiveness, the wind, the physics switches
    and the state changed between steps (each must invalidate the memo), through a fault
    injection (the pending-fault path) and another airframe at the same state."""
    from vtolftc.firmware_sim.vehicle import dynamics as dyn
    from vtolftc.firmware_sim.vehicle import model as vm
    from vtolftc.firmware_sim.vehicle.faults import case_faults

    fast, ref = vm.Vehicle(ds1), vm.Vehicle(ds1)
    fault = case_faults("1", ds1.actuator_names)[0]
    rng = np.random.default_rng(5)
    u_min = np.r_[np.zeros(10), -np.ones(5)]
    hits = 0
    for k in range(400):
        cmds = rng.uniform(u_min, 1.0).astype(np.float32).astype(np.float64)
        for v in (fast, ref):
            if k == 60:
                v.eff[3] = 0.7
            elif k == 90:
                v.wind[:] = (4.0, -1.0, 0.2)
            elif k == 120:
                v.physics = dyn.ALL_PHYSICS & ~dyn.AERODYNAMICS
            elif k == 150:
                v.physics = dyn.ALL_PHYSICS
            elif k == 200:
                s = v.state
                s[3] += 1.0
                v.set_state(s)
            elif k == 250:  # another airframe, the state unchanged (a step of length 0)
                v.packed = dyn.perturb(dyn.pack(ds1), 1.1)
                v.step(None, 0)
            elif k == 320:
                v.inject(fault)  # pending to the end (no memo on that path)
        fast_path = not fast._pending and fast._packed_args[0] is fast.packed
        if fast_path:
            hits += bool(dyn._memo_valid(fast._memo, fast.x, fast.eff, fast.wind,
                                         fast.physics))
        fast.step(cmds, 4)
        if not fast_path:
            ref.step(cmds, 4)  # (the same branch in both: no memo there)
        else:  # every stage evaluated
            assert vm._take_commands(cmds, ref.u)
            pa = ref._packed_args
            dyn.step_n_flat(ref.x, ref.u, ref.eff, ref.stuck, 4, ref.dt_usec * 1e-6, pa[1],
                            pa[2], ref.wind, ref.physics, ref.fm)
            ref.time_usec += 4 * ref.dt_usec
        assert _bits(fast.x) == _bits(ref.x), k
        assert _bits(fast.fm) == _bits(ref.fm), k
    assert hits > 300  # the memo was used


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_vehicle_keeps_its_workspace_views(ds1, how):
    """The vehicle's state arrays are views of one workspace (``Vehicle._pack``, the packed
    control-step kernel reads that): a deep copy or an unpickled vehicle links them to its
    own workspace again and flies on exactly as the original, with the wind changed through
    its attribute in between (a stale view would not reach the kernel)."""
    import pickle

    from vtolftc.firmware_sim.vehicle.model import Vehicle

    orig = Vehicle(ds1)
    rng = np.random.default_rng(8)
    u_min = np.r_[np.zeros(10), -np.ones(5)]
    for _ in range(5):
        orig.step(rng.uniform(u_min, 1.0), 4)
    twin = copy.deepcopy(orig) if how == "deepcopy" else pickle.loads(pickle.dumps(orig))
    for name in Vehicle._WS_PARTS:
        assert np.shares_memory(getattr(twin, name), twin._vws), name
        assert not np.shares_memory(getattr(twin, name), orig._vws), name
    for k in range(40):
        cmds = rng.uniform(u_min, 1.0)
        if k == 20:
            for v in (orig, twin):
                v.wind[:] = (5.0, -3.0, 0.5)
        orig.step(cmds, 4)
        twin.step(cmds, 4)
        assert _bits(twin._vws) == _bits(orig._vws), k
    assert orig.fm[6] != 0.0 and _bits(twin.x) == _bits(orig.x)


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
def test_wire_round_equals_wire_commands_and_the_vehicle_flies_it(ds1):
    """``wire_round`` (compiled) rounds as ``wire_commands`` (numpy's float32 cast), bit for
    bit, on random commands and at the edges (ties, subnormals, float32 overflow, inf, NaN);
    ``Vehicle.step(u, wire=True)`` flies what ``Vehicle.step(wire_commands(u))`` flies, on
    the fused path and through a fault injection (the other path); a command that only the
    rounding makes infinite is refused as the vehicle refuses ``wire_commands``'s inf."""
    from vtolftc.firmware_sim.vehicle import model as vm
    from vtolftc.firmware_sim.vehicle.faults import case_faults
    from vtolftc.protocols.hil import wire_commands, wire_round

    rng = np.random.default_rng(13)
    f32 = np.finfo(np.float32)
    edge = np.array([1.0 + 2.0**-24, 1.0 + 3 * 2.0**-24, -(1.0 + 2.0**-24), 1e-40, -1e-45,
                     float(f32.max) * (1 + 2.0**-25), float(f32.max) * (1 + 2.0**-23), 1e39,
                     -1e39, np.inf, -np.inf, np.nan, 0.0, -0.0, 5e-324, 0.1])
    for k in range(2000):
        u = rng.uniform(-1.0, 1.0, 15) * 10.0 ** rng.integers(-8, 3)
        if k == 0:
            u = edge
        assert _bits(wire_round(u)) == _bits(wire_commands(u)), k
    fast, ref = vm.Vehicle(ds1), vm.Vehicle(ds1)
    fault = case_faults("1", ds1.actuator_names)[0]
    u_min = np.r_[np.zeros(10), -np.ones(5)]
    for k in range(200):
        u = rng.uniform(u_min, 1.0)
        if k == 100:
            fast.inject(fault)
            ref.inject(fault)
        fast.step(u, 4, wire=True)
        ref.step(wire_commands(u), 4)
        assert _bits(fast._vws) == _bits(ref._vws), k
    bad = u.copy()
    bad[3] = 1e39  # finite, beyond float32: inf on the wire
    with pytest.raises(ValueError, match="NaN or inf"):
        fast.step(bad, 4, wire=True)
    with pytest.raises(ValueError, match="NaN or inf"):
        ref.step(wire_commands(bad), 4)
    assert _bits(fast._vws) == _bits(ref._vws)


@pytest.mark.parametrize("n_bp", [1, 2, 3, 5])
def test_packed_ppid_step_equals_unpacked_kernel(ds1, n_bp):
    """``scheduled_ppid3_step_packed`` on a schedule's ``kernel_packed`` and a controller's
    workspace gives, step after step, the moments, gains and state of
    ``scheduled_ppid3_step`` on separate arrays of their own (copies made before the first
    step), for schedules of 1, 2, 3 and 5 breakpoints (the kernel finds n from the table's
    size) and airspeeds below, between, on and above the breakpoints."""
    from vtolftc.firmware_sim.autopilot import control_kernels as ck
    from vtolftc.firmware_sim.autopilot.attitude import ScheduledPPIDController
    from vtolftc.firmware_sim.autopilot.schedule import GainSchedule

    base = Autopilot(ds1, controller="gs-shif").attitude_stage.controller.schedule
    rng = np.random.default_rng(100 + n_bp)
    bps = tuple(float(b) for b in np.sort(rng.choice(np.arange(0.0, 25.0, 1.5), n_bp,
                                                     replace=False)))
    table = {ax: {f: tuple(float(v) * float(rng.uniform(0.5, 1.5)) for v in
                           (list(vals) * n_bp)[:n_bp])
                  for f, vals in fields.items()} for ax, fields in base.table.items()}
    sched = GainSchedule("t", base.airframe_name, base.airframe_sha256, bps, table)
    ctrl = ScheduledPPIDController(sched)
    bp, rows, slopes = (a.copy() for a in sched.kernel_tables)
    G, S, C = (a.copy() for a in ctrl.kernel_arrays[:3])
    out = np.zeros(3)
    for k in range(300):
        V = float(rng.choice([rng.uniform(-2.0, 27.0), rng.choice(bps), np.nan]))
        ref, att, rates = rng.normal(0, 0.3, 3), rng.normal(0, 0.3, 3), rng.normal(0, 0.5, 3)
        flags = [bool(b) for b in rng.random(6) < 0.2]
        mask = sum(b << i for i, b in enumerate(flags))  # bits 0-2 sat_hi, 3-5 sat_lo
        ck.scheduled_ppid3_step_packed(sched.kernel_packed, V, ref, att, rates,
                                       ctrl.kernel_ws, mask)
        ck.scheduled_ppid3_step(bp, rows, slopes, V, ref, att, rates, G, S, C, *flags, out)
        assert ctrl.kernel_arrays[3].tobytes() == out.tobytes(), k
        assert ctrl.kernel_arrays[0].tobytes() == G.tobytes(), k
        assert ctrl.kernel_arrays[1].tobytes() == S.tobytes(), k


def test_ppid_workspace_views_survive_copy_and_pickle(ds1):
    """A deep copy and a pickle of a controller stepped mid-flight: their axes' state and
    ``kernel_arrays`` are views of their own workspace (what the packed kernel writes, the
    axes read), and they step on as the original does, bit for bit."""
    import pickle

    from vtolftc.firmware_sim.autopilot import control_kernels as ck

    ctrl = Autopilot(ds1, controller="gs-shif").attitude_stage.controller
    rng = np.random.default_rng(7)

    def step(c, V, ref, att, rates):
        ck.scheduled_ppid3_step_packed(c.schedule.kernel_packed, V, ref, att, rates,
                                       c.kernel_ws, 0)
        return c.kernel_arrays[3].copy()

    for _ in range(20):
        step(ctrl, 8.0, *rng.normal(0, 0.3, (3, 3)))
    copies = [copy.deepcopy(ctrl), pickle.loads(pickle.dumps(ctrl))]
    for c in copies:
        assert c.kernel_ws is not ctrl.kernel_ws
        for arr in (*c.kernel_arrays, *(p._state for p in c.pids), *(p._const for p in c.pids)):
            assert np.shares_memory(arr, c.kernel_ws)
    for _ in range(50):
        args = (float(rng.uniform(0, 20)), *rng.normal(0, 0.3, (3, 3)))
        want = step(ctrl, *args)
        for c in copies:
            assert step(c, *args).tobytes() == want.tobytes()
            assert [p.integral for p in c.pids] == [p.integral for p in ctrl.pids]
            assert c.pids[1].gains == ctrl.pids[1].gains


def _ref_mc_alt(st, h_ref, h, v_up, kp_z, kp_vz, ki_vz, v_max_up, v_max_dn, override):
    """MulticopterAltitudeHold.update as it was, with the builtins min / max (st: integral,
    dt, a_up_max, a_dn_max, i_limit; returns (a_up, integral, v_ref))."""
    integral, dt, a_up_max, a_dn_max, i_limit = st
    v_ref = (min(max(kp_z * (h_ref - h), -v_max_dn), v_max_up) if override is None
             else float(override))
    e = v_ref - v_up
    p = kp_vz * e
    dI = ki_vz * e * dt
    u = p + integral + dI
    if (u > a_up_max and dI > 0.0) or (u < -a_dn_max and dI < 0.0):
        dI = 0.0
    integral = min(max(integral + dI, -i_limit), i_limit)
    return min(max(p + integral, -a_dn_max), a_up_max), integral, v_ref


def _ref_fw_alt(integral, dt, h_ref, h, v_up, kp_alt, kp_vz, ki_vz, climb_max, sink_max,
                pitch_min, pitch_max):
    """FixedWingAltitudeHold.update as it was, with the builtins min / max."""
    v_ref = min(max(kp_alt * (h_ref - h), -sink_max), climb_max)
    e = v_ref - v_up
    p = kp_vz * e
    dI = ki_vz * e * dt
    u = p + integral + dI
    if (u > pitch_max and dI > 0.0) or (u < pitch_min and dI < 0.0):
        dI = 0.0
    integral = min(max(integral + dI, pitch_min), pitch_max)
    return min(max(p + integral, pitch_min), pitch_max), integral, v_ref


def _adversarial(rng, scale):
    """A random float, or now and then a NaN, an infinity, a signed zero or a bound."""
    r = rng.random()
    if r < 0.03:
        return float("nan")
    if r < 0.06:
        return float(rng.choice([np.inf, -np.inf]))
    if r < 0.12:
        return float(rng.choice([0.0, -0.0]))
    return float(rng.normal(0.0, scale))


def _same(a, b):
    return np.array([a], dtype=float).tobytes() == np.array([b], dtype=float).tobytes()


def test_altitude_holds_clip_as_the_builtins_did():
    """Both altitude holds (their min / max written as comparisons) against the builtins'
    formulas, bit for bit including NaN, infinities and signed zeros, over random steps with
    the integral carried on (landing overrides, saturating and zero-width limits)."""
    from vtolftc.firmware_sim.autopilot.altitude import (
        FixedWingAltitudeHold,
        MulticopterAltitudeHold,
    )

    rng = np.random.default_rng(5)
    mc, fw = MulticopterAltitudeHold(0.004), FixedWingAltitudeHold(0.004)
    mc_i = fw_i = 0.0
    for k in range(20000):
        a = [_adversarial(rng, s) for s in (30.0, 30.0, 5.0, 2.0, 3.0, 2.0, 4.0, 3.0)]
        if k % 500 == 0:  # start again from finite integrals after a NaN got in
            mc.integral = mc_i = float(rng.normal())
            fw.integral = fw_i = float(rng.normal(0.0, 0.1))
        override = None if rng.random() < 0.8 else a[7]
        want = _ref_mc_alt((mc_i, mc.dt, mc.a_up_max, mc.a_dn_max, mc.i_limit), a[0], a[1],
                           a[2], a[3], a[4], a[5], abs(a[6]), abs(a[7]), override)
        got = mc.update(a[0], a[1], a[2], kp_z=a[3], kp_vz=a[4], ki_vz=a[5], v_max_up=abs(a[6]),
                        v_max_dn=abs(a[7]), v_up_override=override)
        mc_i = want[1]
        assert _same(got, want[0]) and _same(mc.integral, want[1]), k
        assert _same(mc.v_up_ref, want[2]), k
        lo = -abs(a[6]) * 0.3
        hi = lo if rng.random() < 0.05 else abs(a[7]) * 0.3
        want = _ref_fw_alt(fw_i, fw.dt, a[0], a[1], a[2], a[3] * 0.1, a[4] * 0.1, a[5] * 0.1,
                           abs(a[6]), abs(a[7]), lo, hi)
        got = fw.update(a[0], a[1], a[2], kp_alt=a[3] * 0.1, kp_vz=a[4] * 0.1,
                        ki_vz=a[5] * 0.1, climb_max=abs(a[6]), sink_max=abs(a[7]),
                        pitch_min=lo, pitch_max=hi)
        fw_i = want[1]
        assert _same(got, want[0]) and _same(fw.integral, want[1]), k
        assert _same(fw.v_up_ref, want[2]), k


def test_outer_loop_helpers_clip_as_the_builtins_did(ds1):
    """``aero_estimate`` and ``pusher_max_force`` (min / max as comparisons) against the
    builtins' formulas, bit for bit, on random and adversarial airspeeds and angles."""
    ap = Autopilot(ds1)
    outer = ap.outer
    w = ds1.wing
    rho = ap.effectiveness._rho
    rng = np.random.default_rng(9)
    for k in range(20000):
        V = abs(_adversarial(rng, 15.0)) if rng.random() < 0.9 else float(rng.uniform(0, 2))
        alpha = _adversarial(rng, 0.3)
        tot = 0.0
        for r in ds1.pushers:
            tot += r.max_thrust_N * min(1.25, max(0.0, 1.0 - V / r.zero_thrust_axial_speed_m_s))
        assert _same(outer.pusher_max_force(V), tot), (k, V)
        if V < 1.0:
            continue
        qS = 0.5 * rho * V * V * w.area_m2
        cl = min(max(w.CL0 + w.CL_alpha * alpha, -w.CL_max), w.CL_max)
        lift, drag = outer.aero_estimate(V, alpha)
        assert _same(lift, qS * cl) and _same(drag, qS * (w.CD0 + w.induced_drag_factor * cl * cl))


def _hypot2_many(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    import numba

    from vtolftc.firmware_sim.autopilot.outer_kernels import hypot2

    @numba.njit
    def many(x, y, out):  # pragma: no cover - compiled
        for i in range(x.size):
            out[i] = hypot2(x[i], y[i])

    out = np.empty(x.size)
    many(x, y, out)
    return out


def test_hypot2_is_cpythons_math_hypot_bit_for_bit():
    """The compiled port of CPython's ``math.hypot`` against ``math.hypot`` itself on 10^6
    random pairs whose exponents span the whole double range (subnormals to overflow), pairs
    of nearly equal magnitude, and adversarial pairs (signed zeros, subnormals, the largest
    double, infinities, NaN, equal values).

    The port is 3.11's algorithm, so the flight's bits do not depend on the interpreter.
    CPython 3.12 changed the branch for a subnormal maximum (3.12.1 and 3.13.0 differ from the
    port in 34 of these pairs, all with max(|x|, |y|) subnormal, and nowhere else): on other
    versions those pairs are left out of the comparison."""
    import math
    import sys

    rng = np.random.default_rng(15)
    n = 1_000_000
    e1 = rng.uniform(-1085.0, 1030.0, n)
    e2 = np.clip(e1 + rng.uniform(-60.0, 60.0, n), -1085.0, 1023.0)
    with np.errstate(over="ignore"):
        x = rng.uniform(-2.0, 2.0, n) * np.exp2(e1)
        y = rng.uniform(-2.0, 2.0, n) * np.exp2(e2)
    x[: n // 10] = rng.normal(0.0, 3.0, n // 10)  # the position hold's range
    y[: n // 10] = rng.normal(0.0, 3.0, n // 10)
    near = slice(n // 10, n // 5)  # ratios near 1
    y[near] = x[near] * (1.0 + rng.normal(0.0, 1e-9, n // 10))
    special = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-310,
               1.7976931348625157e308, -1.7976931348625157e308, math.inf, -math.inf,
               math.nan, 1.0, 3.0, 4.0, 1e154, 1e-154]
    sx, sy = np.meshgrid(special, special)
    x = np.concatenate([x, sx.ravel(), [1.5, 1e300, 7e-320]])
    y = np.concatenate([y, sy.ravel(), [1.5, 1e300, 7e-320]])
    got = _hypot2_many(x, y)
    want = np.array([math.hypot(a, b) for a, b in zip(x.tolist(), y.tolist(), strict=True)])
    differ = got.view(np.int64) != want.view(np.int64)
    if sys.version_info[:2] != (3, 11):
        differ &= ~(np.maximum(np.abs(x), np.abs(y)) < 2.2250738585072014e-308)
    bad = np.flatnonzero(differ)
    assert bad.size == 0, [(x[i], y[i], got[i], want[i]) for i in bad[:5]]


def _ref_position_hold(pos, vel, hold_ne, locked, kp, vmax, kv, g, yaw, tilt_max_deg):
    """``OuterLoops._position_hold`` as it was in Python (session 14): roll and pitch
    references, the held position, locked."""
    import math

    vn, ve = float(vel[0]), float(vel[1])
    if not locked:
        if math.hypot(vn, ve) < 0.5:
            hold_ne[:] = pos[:2]
            locked = True
        vrn, vre = 0.0, 0.0
    else:
        vrn = kp * (hold_ne[0] - float(pos[0]))
        vre = kp * (hold_ne[1] - float(pos[1]))
        s = math.hypot(vrn, vre)
        if s > vmax:
            vrn, vre = vrn * vmax / s, vre * vmax / s
    an, ae = kv * (vrn - vn), kv * (vre - ve)
    a_fwd = math.cos(yaw) * an + math.sin(yaw) * ae
    a_right = -math.sin(yaw) * an + math.cos(yaw) * ae
    tmax = math.radians(tilt_max_deg)
    pitch_ref = min(max(-math.atan2(a_fwd, g), -tmax), tmax)
    roll_ref = min(max(math.atan2(a_right, g), -tmax), tmax)
    return roll_ref, pitch_ref, locked


def test_position_hold_kernel_equals_the_python_it_replaces():
    """``position_hold_step`` against the Python position hold, bit for bit (references, held
    position, lock) on random states: braking and locking (speeds around 0.5 m/s), locked with
    the velocity reference under and over ``MPC_XY_VEL_MAX``, adversarial values."""
    from vtolftc.firmware_sim.autopilot.outer_kernels import position_hold_step

    rng = np.random.default_rng(16)
    ref = np.zeros(3)
    for k in range(30000):
        pos = rng.normal(0.0, 20.0, 3)
        vel = rng.normal(0.0, 0.4 if k % 3 else 3.0, 3)
        if k % 97 == 5:
            vel[int(rng.integers(2))] = _adversarial(rng, 1.0)
        hold = rng.normal(0.0, 20.0, 2) if k % 2 else pos[:2] + rng.normal(0.0, 0.5, 2)
        locked = bool(rng.random() < 0.6)
        kp, vmax, kv = float(rng.uniform(0.1, 2.0)), float(rng.uniform(0.5, 12.0)), float(
            rng.uniform(0.5, 5.0))
        yaw = float(rng.uniform(-4.0, 4.0))
        tilt = float(rng.choice([20.0, 35.0, 45.0, rng.uniform(1.0, 60.0)]))
        h_ref = hold.copy()
        want = _ref_position_hold(pos, vel, h_ref, locked, kp, vmax, kv, 9.80665, yaw, tilt)
        h_got = hold.copy()
        ref[:] = np.nan
        got_locked = position_hold_step(pos, vel, h_got, ref, locked, kp, vmax, kv, 9.80665,
                                        yaw, tilt)
        assert got_locked == want[2], k
        assert _bits(ref[:2]) == _bits(np.array([want[0], want[1]])), k
        assert _bits(h_got) == _bits(h_ref), k


def _ref_mc_hold(pos, vel, hold_ne, ref, v, c, locked, integral, h_ref, h, v_up, kp_z, kp_vz,
                 ki_vz, v_max_up, v_max_dn, override, use_override, cos_tilt, fz_aero, kp_xy,
                 vmax_xy, kv_xy, yaw, tilt_max_deg):
    """``_outer_mc``'s TAKEOFF / HOVER / LAND path as it was in Python (session 14), on
    ``mc_hold_step``'s arguments: writes ``hold_ne``, ``ref``, ``v``; returns ``(locked,
    integral, v_up_ref)``."""
    a_up, integral, v_ref = _ref_mc_alt((integral, c[4], c[5], c[6], c[7]), h_ref, h, v_up,
                                        kp_z, kp_vz, ki_vz, v_max_up, v_max_dn,
                                        override if use_override else None)
    v[0] = (-float(c[0]) * (float(c[1]) + a_up) / cos_tilt - fz_aero)
    roll_ref, pitch_ref, locked = _ref_position_hold(pos, vel, hold_ne, locked, kp_xy, vmax_xy,
                                                     kv_xy, float(c[1]), yaw, tilt_max_deg)
    ref[0], ref[1] = roll_ref, pitch_ref
    v[1] = 0.0
    return locked, integral, v_ref


def test_mc_hold_step_on_a_real_flights_inputs(ds1, monkeypatch):
    """Case 1's first 12 s (take-off and hover: ``mc_hold_step`` at every multicopter step)
    with the kernel's every call checked against the Python it replaces (altitude hold, z
    force, position hold), bit for bit; then random calls around those inputs (braking and
    locking, the landing override, saturating limits)."""
    from vtolftc.firmware_sim.autopilot import outer_loops
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    kernel = outer_loops.mc_hold_step
    calls = []

    def check(args):
        pos, vel, hold_ne, ref, v, c = args[:6]
        w_hold, w_ref, w_v = hold_ne.copy(), ref.copy(), v.copy()
        want = _ref_mc_hold(pos, vel, w_hold, w_ref, w_v, c, *args[6:])
        got = kernel(*args)
        assert got == want
        assert _bits(ref) == _bits(w_ref) and _bits(v) == _bits(w_v)
        assert _bits(hold_ne) == _bits(w_hold)
        return got

    def checked(*args):
        calls.append(tuple(a.copy() if isinstance(a, np.ndarray) else a for a in args))
        return check(args)

    monkeypatch.setattr(outer_loops, "mc_hold_step", checked)
    run_scenario(paper_scenario("1", 12.0), "gs-shif")
    assert len(calls) > 1000
    rng = np.random.default_rng(20)
    for k in range(5000):
        args = list(calls[int(rng.integers(len(calls)))])
        args[0] = args[0] + rng.normal(0.0, 3.0, 3)  # pos
        args[1] = args[1] * float(rng.choice([0.0, 1.0, 30.0])) + rng.normal(0.0, 0.3, 3)
        args[6] = bool(rng.random() < 0.5)  # locked
        args[7] = float(rng.normal(0.0, 3.0))  # integral
        args[10] = float(rng.normal(0.0, 4.0))  # v_up
        args[16], args[17] = -float(rng.uniform(0.1, 2.0)), bool(k % 4 == 0)  # landing
        args[19] = float(rng.normal(0.0, 50.0))  # fz_aero
        args[3], args[4] = np.full(3, np.nan), args[4].copy()  # what the step must write
        args[4][:2] = np.nan
        check(tuple(args))


def _ref_estimate_update(st: dict, nav: NavState):
    """``StateEstimate.update`` as it was in Python (session 14) on a dict of its fields,
    with the body-axis velocity the outer loops computed from its ``ql`` and ``vel``."""
    import math

    from vtolftc.firmware_sim.autopilot.estimate import body_velocity_f

    pos = nav.pos_ned_m.tolist()
    vel = nav.vel_ned_m_s.tolist()
    ql = nav.q_wxyz.tolist()
    isf = math.isfinite
    if not (isf(pos[0]) and isf(pos[1]) and isf(pos[2]) and isf(vel[0]) and isf(vel[1])
            and isf(vel[2]) and isf(ql[0]) and isf(ql[1]) and isf(ql[2]) and isf(ql[3])):
        return None
    p_, q_, r_ = nav.omega_body_rad_s.tolist()
    if not (isf(p_) and isf(q_) and isf(r_)):
        return None
    st["time_usec"] = int(nav.time_usec)
    w, x, y, z = ql
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    ub, _, wb = body_velocity_f(*ql, *vel)
    st["ub"], st["wb"] = ub, wb
    st["alt"] = h = -pos[2]
    st["v_up"] = -vel[2]
    V = float(nav.airspeed_m_s)
    st["airspeed"] = V if math.isfinite(V) else 0.0
    if not math.isfinite(st["ground_alt"]):
        st["ground_alt"] = h
    st["euler"] = (roll, pitch, yaw)
    return st["euler"]


def test_estimate_kernel_equals_the_python_it_replaces():
    """``StateEstimate.update`` (``estimate_step``) against the Python update it replaces,
    field by field and bit for bit, on random samples with now and then a non-finite entry
    (rejected, nothing changed), a NaN airspeed, and attitudes at the gimbal lock."""
    rng = np.random.default_rng(17)
    est = StateEstimate()
    st = {"time_usec": 0, "euler": (0.0, 0.0, 0.0), "ub": 0.0, "wb": 0.0, "alt": 0.0,
          "v_up": 0.0, "airspeed": 0.0, "ground_alt": float("nan")}
    h = np.sqrt(0.5)
    for k in range(20000):
        a = rng.normal(0.0, 1.0, 13) * [1, 1, 1, 1, 2, 2, 2, 50, 50, 30, 10, 10, 3]
        q = a[0:4] / np.linalg.norm(a[0:4])
        if k % 50 == 7:
            q = np.array([h, 0.0, h if k % 100 == 7 else -h, 0.0])
        buf = np.concatenate([q, a[4:13]])
        if k % 13 == 4:
            buf[int(rng.integers(13))] = _adversarial(rng, 1.0) if k % 2 else np.nan
        air = float(rng.uniform(0, 30)) if k % 17 else float("nan")
        nav = NavState(k * 4000, buf[0:4], buf[4:7], buf[7:10], buf[10:13], air)
        want = _ref_estimate_update(st, nav)
        got = est.update(nav)
        assert (got is None) == (want is None), k
        for name in ("time_usec", "ub", "wb", "alt", "v_up", "airspeed", "ground_alt"):
            assert _same(getattr(est, name), st[name]), (k, name)
        assert np.array(est.euler).tobytes() == np.array(st["euler"]).tobytes(), k
        assert est.att.tobytes() == np.array(st["euler"]).tobytes(), k


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_estimate_keeps_its_workspace_view(how):
    """``StateEstimate.att`` stays a view of the copy's own workspace after copy and pickle."""
    import pickle

    est = StateEstimate()
    q = np.array([0.9, 0.1, -0.2, 0.3])
    est.update(_nav(q / np.linalg.norm(q), np.zeros(3)))
    c = copy.deepcopy(est) if how == "deepcopy" else pickle.loads(pickle.dumps(est))
    assert c.att.tobytes() == est.att.tobytes() and c.euler == est.euler
    q2 = np.array([0.5, 0.5, 0.5, -0.5])
    c.update(_nav(q2, np.zeros(3)))
    assert c.att.tobytes() == np.array(c.euler).tobytes()
    assert est.att.tobytes() == np.array(est.euler).tobytes() != c.att.tobytes()


def _ref_outer_aero(outer, roll, pitch, ub, wb, V, lim):
    """The Python of ``OuterLoops.update``'s first lines and of ``aero_estimate`` as they were
    (session 14): cos_tilt, alpha, lift, drag, fz_aero."""
    import math

    w = outer.airframe.wing
    rho = outer.effectiveness._rho
    cos_tilt = max(0.5, math.cos(roll) * math.cos(pitch))
    alpha = math.atan2(wb, ub) if ub > 1.0 else 0.0
    a = alpha if lim is None else min(alpha, lim)
    if V < 1.0:
        lift, drag = 0.0, 0.0
    else:
        qS = 0.5 * rho * V * V * w.area_m2
        cl = min(max(w.CL0 + w.CL_alpha * a, -w.CL_max), w.CL_max)
        lift, drag = qS * cl, qS * (w.CD0 + w.induced_drag_factor * cl * cl)
    fz_aero = -lift * math.cos(alpha) - drag * math.sin(alpha)
    return cos_tilt, alpha, lift, drag, fz_aero


def test_outer_aero_kernel_equals_the_python_it_replaces(ds1):
    """``outer_aero_step`` against the outer loops' Python preamble and ``aero_estimate`` as
    they were, bit for bit: random and adversarial attitudes, body velocities (``ub`` around
    1 m/s), airspeeds (around 1 m/s) and a degraded-lift angle limit (none: +inf)."""
    import math

    from vtolftc.firmware_sim.autopilot.outer_kernels import outer_aero_step

    outer = Autopilot(ds1).outer
    wing = outer._wing_constants()
    out = np.zeros(5)
    rng = np.random.default_rng(18)
    for k in range(30000):
        # (never infinite: math.cos(inf) raises; the estimate's angles are atan2 / asin's)
        roll, pitch = (x if not math.isinf(x) else math.nan
                       for x in (_adversarial(rng, 0.8), _adversarial(rng, 0.8)))
        ub = _adversarial(rng, 10.0) if k % 4 else float(rng.uniform(0.0, 2.0))
        wb = _adversarial(rng, 2.0)
        V = abs(_adversarial(rng, 15.0)) if k % 5 else float(rng.uniform(0.0, 2.0))
        lim = None if k % 3 else _adversarial(rng, 0.2)
        out[:] = np.nan
        outer_aero_step(roll, pitch, ub, wb, V, math.inf if lim is None else lim, wing, out)
        want = _ref_outer_aero(outer, roll, pitch, ub, wb, V, lim)
        assert out.tobytes() == np.array(want).tobytes(), (k, out, want)


def _ref_fw_longitudinal(outer, fw_i, as_i, h_ref, h, v_up, V, pitch, alpha, lift, drag, g_,
                         v_sp):
    """``OuterLoops._outer_fw``'s altitude and airspeed loops as they were in Python
    (session 14): pitch_ref, fw integral, v_up_ref, airspeed integral, fx."""
    import math

    mass, g = outer.airframe.mass_kg, outer.airframe.gravity_m_s2
    ref1, fw_i2, v_ref = _ref_fw_alt(fw_i, outer.fw_alt.dt, h_ref, h, v_up, g_[0], g_[1],
                                     g_[2], g_[3], g_[4], math.radians(g_[5]),
                                     math.radians(g_[6]))
    tot = 0.0
    for r in outer.airframe.pushers:
        tot += r.max_thrust_N * min(1.25, max(0.0, 1.0 - V / r.zero_thrust_axial_speed_m_s))
    fx_max = tot
    e_v = v_sp - V
    a_x = g_[7] * e_v + as_i
    fx_cmd = drag * math.cos(alpha) - lift * math.sin(alpha) + mass * (
        a_x + g * math.sin(pitch))
    if not ((fx_cmd >= fx_max and e_v > 0) or (fx_cmd <= 0.0 and e_v < 0)):
        as_i = min(max(as_i + g_[8] * e_v * outer.dt, -3.0), 3.0)
    return ref1, fw_i2, v_ref, as_i, min(max(fx_cmd, 0.0), fx_max)


def test_fw_longitudinal_kernel_equals_the_python_it_replaces(ds1):
    """``fw_longitudinal_step`` (the fixed-wing altitude law, the pushers' maximum force and
    the airspeed hold) against the Python of ``_outer_fw`` as it was, bit for bit, over random
    steps with both integrals carried on (saturating pushers, negative force commands,
    adversarial values; a NaN result need only be NaN, see below)."""
    import math

    from vtolftc.firmware_sim.autopilot.outer_kernels import fw_longitudinal_step

    outer = Autopilot(ds1).outer
    rng = np.random.default_rng(19)
    fw_i, as_i = 0.05, 0.0
    for k in range(20000):
        if k % 500 == 0:  # finite integrals again after a NaN got in
            fw_i, as_i = float(rng.normal(0.0, 0.1)), float(rng.normal(0.0, 1.0))
        h_ref, h = float(rng.normal(100.0, 5.0)), _adversarial(rng, 100.0)
        v_up, V = _adversarial(rng, 3.0), abs(_adversarial(rng, 15.0))
        pitch = float(rng.normal(0.0, 0.2))
        alpha = float(rng.normal(0.0, 0.1)) if k % 7 else _adversarial(rng, 0.1)
        lift, drag = _adversarial(rng, 200.0), abs(float(rng.normal(0.0, 30.0)))
        gains = [float(x) for x in (rng.uniform(0.05, 1.0), rng.uniform(0.0, 0.1),
                                    rng.uniform(0.0, 0.05), rng.uniform(0.5, 5.0),
                                    rng.uniform(0.5, 5.0), rng.uniform(-30.0, 0.0),
                                    rng.uniform(0.0, 30.0), rng.uniform(0.0, 2.0),
                                    rng.uniform(0.0, 1.0))]
        v_sp = float(rng.uniform(10.0, 25.0))
        if math.isinf(v_up) or math.isinf(V) or math.isinf(alpha):
            continue  # (math.cos / sin of inf raise; the estimate's values are finite)
        want = _ref_fw_longitudinal(outer, fw_i, as_i, h_ref, h, v_up, V, pitch, alpha, lift,
                                    drag, gains, v_sp)
        got = fw_longitudinal_step(outer._pushers, outer._consts, h_ref, h, v_up, V, pitch,
                                   alpha, lift, drag, fw_i, *gains[:7], v_sp, *gains[7:],
                                   as_i)
        # equal bits, or NaN where the Python gave NaN: a NaN's sign bit follows the operand
        # order the compiler picks for a commutative + or *, and nothing reads it (the
        # allocator rejects any non-finite command); a flight's values are finite here
        g_, w_ = np.array(got), np.array(want)
        same = (g_.view(np.int64) == w_.view(np.int64)) | (np.isnan(g_) & np.isnan(w_))
        assert same.all(), (k, got, want)
        fw_i, as_i = want[1], want[3]


def _ref_transition(outer, ma, front, ramp, h_ref, h, v_up, V, cos_tilt, fz_aero, g_, ref,
                    v):
    """``OuterLoops._outer_mc``'s front / back transition branch as it was in Python
    (session 15; ``ma`` a copy of the altitude hold): writes ``ref[0:2]`` and ``v[0:2]``,
    returns the pusher ramp."""
    af = outer.airframe
    a_up = ma.update(h_ref, h, v_up, kp_z=g_[0], kp_vz=g_[1], ki_vz=g_[2], v_max_up=g_[3],
                     v_max_dn=g_[4], v_up_override=None)
    v[0] = (-af.mass_kg * (af.gravity_m_s2 + a_up) / cos_tilt - fz_aero)
    fx_cmd = 0.0
    if front:
        ref[0] = 0.0
        ref[1] = 0.0
        r = ramp + g_[5] * outer.dt
        ramp = r if r < 1.0 else 1.0
        fx_cmd = g_[6] * ramp * outer.pusher_max_force(V)
    else:
        ref[0] = 0.0
        ref[1] = 0.0
    v[1] = fx_cmd
    return ramp


def test_transition_and_z_force_kernels_equal_the_python_they_replace(ds1):
    """``mc_transition_step`` (front and back transition: altitude law, z force, references,
    pusher ramp) and ``mc_z_force_step`` (fixed-wing while the lift rotors ramp down, and
    with a climb-rate override) against the Python they replaced, bit for bit over random
    steps with the integral and ramp carried on (adversarial values; a NaN need only be NaN,
    as for ``fw_longitudinal_step``)."""
    import copy as _copy

    from vtolftc.firmware_sim.autopilot.outer_kernels import mc_transition_step, mc_z_force_step

    outer = Autopilot(ds1).outer
    rng = np.random.default_rng(24)
    integral, ramp = 0.1, 0.0
    for k in range(20000):
        if k % 400 == 0:  # finite state again after a NaN got in
            integral, ramp = float(rng.normal(0.0, 1.0)), float(rng.uniform(0.0, 1.2))
        h_ref, h = float(rng.normal(30.0, 5.0)), _adversarial(rng, 30.0)
        v_up, V = _adversarial(rng, 3.0), abs(_adversarial(rng, 12.0))
        cos_tilt = float(rng.uniform(0.5, 1.0)) if k % 9 else _adversarial(rng, 1.0)
        fz_aero = _adversarial(rng, 50.0)
        if cos_tilt == 0.0:  # both raise ZeroDivisionError (a flight's is >= 0.5)
            continue
        g_ = [float(x) for x in (rng.uniform(0.1, 2.0), rng.uniform(0.5, 5.0),
                                 rng.uniform(0.0, 2.0), rng.uniform(0.5, 5.0),
                                 rng.uniform(0.5, 3.0), rng.uniform(0.0, 2.0),
                                 rng.uniform(0.0, 1.0))]
        ma = _copy.copy(outer.mc_alt)
        ma.integral = integral
        ref_w, v_w = rng.normal(size=3), rng.normal(size=5)
        ref_g, v_g = ref_w.copy(), v_w.copy()
        if k % 3 < 2:
            front = k % 3 == 0
            ramp_w = _ref_transition(outer, ma, front, ramp, h_ref, h, v_up, V, cos_tilt,
                                     fz_aero, g_, ref_w, v_w)
            got = mc_transition_step(v_g, ref_g, outer._consts, outer._pushers, integral,
                                     h_ref, h, v_up, *g_[:5], cos_tilt, fz_aero, front, ramp,
                                     g_[5], g_[6], V)
            want = (ma.integral, ma.v_up_ref, ramp_w)
        else:  # the z force alone, with or without a climb-rate override (landing)
            ov = float(rng.normal(0.0, 1.0)) if k % 2 else None
            a_up = ma.update(h_ref, h, v_up, kp_z=g_[0], kp_vz=g_[1], ki_vz=g_[2],
                             v_max_up=g_[3], v_max_dn=g_[4], v_up_override=ov)
            v_w[0] = -ds1.mass_kg * (ds1.gravity_m_s2 + a_up) / cos_tilt - fz_aero
            got = mc_z_force_step(v_g, outer._consts, integral, h_ref, h, v_up, *g_[:5],
                                  0.0 if ov is None else ov, ov is not None, cos_tilt,
                                  fz_aero)
            want = (ma.integral, ma.v_up_ref)
        g_a = np.r_[np.array(got), v_g, ref_g]
        w_a = np.r_[np.array(want), v_w, ref_w]
        same = (g_a.view(np.int64) == w_a.view(np.int64)) | (np.isnan(g_a) & np.isnan(w_a))
        assert same.all(), (k, got, want, v_g, v_w)
        integral = want[0]
        if len(want) == 3:
            ramp = want[2]


def _session15_outer_mc(orig):
    """``OuterLoops._outer_mc`` with its front / back transition branch as it was in Python
    (session 15); the other modes through ``orig``."""
    def outer_mc(self, mode, nav, yaw, h, v_up, V, cos_tilt, fz_aero):
        if mode not in (FlightMode.FRONT_TRANSITION, FlightMode.BACK_TRANSITION):
            return orig(self, mode, nav, yaw, h, v_up, V, cos_tilt, fz_aero)
        pp, sp = self._p, self.sp
        ref = sp.ref
        a_up = self.mc_alt.update(sp.alt_ref, h, v_up, kp_z=pp["MPC_Z_P"].value,
                                  kp_vz=pp["MPC_Z_VEL_P_ACC"].value,
                                  ki_vz=pp["MPC_Z_VEL_I_ACC"].value,
                                  v_max_up=pp["MPC_Z_VEL_MAX_UP"].value,
                                  v_max_dn=pp["MPC_Z_VEL_MAX_DN"].value, v_up_override=None)
        sp.v[0] = (-self.airframe.mass_kg * (self.airframe.gravity_m_s2 + a_up) / cos_tilt
                   - fz_aero)
        fx_cmd = 0.0
        pusher_hi = 1.0
        ref[0] = 0.0
        ref[1] = 0.0
        if mode == FlightMode.FRONT_TRANSITION:
            r = self.pusher_ramp + pp["VT_PSHER_SLEW"].value * self.dt
            self.pusher_ramp = r if r < 1.0 else 1.0
            fx_cmd = pp["VT_F_TRANS_THR"].value * self.pusher_ramp * self.pusher_max_force(V)
        else:
            pusher_hi = 0.0
        sp.v[1] = fx_cmd
        return pusher_hi

    return outer_mc


def _session15_outer_fw(orig):
    """``OuterLoops._outer_fw`` with the lift rotors' z force (before the reserve) as it was
    in Python (session 15): ``orig`` with the reserve's flag, then the z force on top."""

    def outer_fw(self, nav, roll, pitch, yaw, h, v_up, V, cos_tilt, alpha, lift, drag,
                 fz_aero, reserve):
        orig(self, nav, roll, pitch, yaw, h, v_up, V, cos_tilt, alpha, lift, drag, fz_aero,
             True)  # the lateral, altitude and airspeed loops; v[0] = 0
        if not reserve:
            pp, sp = self._p, self.sp
            a_up = self.mc_alt.update(sp.alt_ref, h, v_up, kp_z=pp["MPC_Z_P"].value,
                                      kp_vz=pp["MPC_Z_VEL_P_ACC"].value,
                                      ki_vz=pp["MPC_Z_VEL_I_ACC"].value,
                                      v_max_up=pp["MPC_Z_VEL_MAX_UP"].value,
                                      v_max_dn=pp["MPC_Z_VEL_MAX_DN"].value)
            sp.v[0] = (-self.airframe.mass_kg * (self.airframe.gravity_m_s2 + a_up) / cos_tilt
                       - fz_aero)

    return outer_fw


def test_transition_flight_equals_the_session15_python(ds1, monkeypatch):
    """Case 1 to 32 s (take-off, hover, front transition, fixed-wing with the lift rotors
    ramping down and then the reserve, the faults at 22 s): every step's commands equal, bit
    for bit, to a flight whose outer loops run the Python the transition and z-force kernels
    replaced (which parameter goes where included)."""
    import hashlib

    from vtolftc.firmware_sim.autopilot.outer_loops import OuterLoops
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    def fly():
        h, modes = hashlib.sha256(), []

        def setup(ap):
            step = ap.step
            moved = set()

            def rec(nav):
                # altitude steps on entering the transition (up) and fixed-wing (down): the
                # climb and descent limits bind there (each parameter must reach its place)
                m = ap.modes.mode
                if m in (FlightMode.FRONT_TRANSITION, FlightMode.FIXED_WING) \
                        and m not in moved:
                    moved.add(m)
                    ap.setpoints.alt_ref += 15.0 if m is FlightMode.FRONT_TRANSITION else -25.0
                u = step(nav)
                h.update(u.tobytes())
                modes.append((ap.modes.mode, ap.output._fw_reserve))
                return u

            ap.step = rec

        run_scenario(paper_scenario("1", 32.0), "gs-shif", autopilot_setup=setup)
        return h.hexdigest(), modes

    now, modes = fly()
    monkeypatch.setattr(OuterLoops, "_outer_mc", _session15_outer_mc(OuterLoops._outer_mc))
    monkeypatch.setattr(OuterLoops, "_outer_fw", _session15_outer_fw(OuterLoops._outer_fw))
    then, modes_then = fly()
    assert modes == modes_then
    assert (FlightMode.FRONT_TRANSITION, False) in modes
    assert (FlightMode.FIXED_WING, False) in modes and (FlightMode.FIXED_WING, True) in modes
    assert now == then


def test_allocate_tracked_v_tail_equals_writing_v_first(ds1):
    """``allocate_tracked(..., v_tail=tau)`` (the output stage's ``v[2:] = tau`` inside the
    compiled call) against ``v[2:] = tau`` in Python and then ``allocate_tracked``: the same
    ``v``, command, status, mask, ``(B u)[0]`` and warm start, step after step, over random
    problems with stale entries in ``v``'s tail, infeasible demands and a non-finite moment
    (the invalid-input path reads the written ``v``)."""
    ap = Autopilot(ds1)
    one: ActiveSetAllocator = ap.output.allocator
    two: ActiveSetAllocator = Autopilot(ds1).output.allocator
    eff = EffectivenessModel(ds1)
    rng = np.random.default_rng(16)
    n_u = one.n_u
    u1, u2 = np.empty(n_u), np.empty(n_u)
    statuses = set()
    for k in range(300):
        B = eff.matrix_on_grid(float(rng.choice([0.0, 7.3, 17.9])), 0.1)
        v = np.array([-ds1.weight_N, 5.0, 0.0, 0.0, 0.0]) + rng.normal(0, 1, 5) * [
            60.0, 20.0, 15.0, 15.0, 5.0] * (4.0 if k % 11 == 5 else 1.0)
        if k == 150:
            v[3] = np.nan
        hi = np.ones(n_u)
        hi[: ap.n_rotors] = float(rng.choice([1.0, 0.6]))
        pref = ap.u_pref_mc if k % 2 else ap.u_pref_fw
        v2 = v.copy()
        v2[2:] = rng.normal(0, 100.0, 3) if k % 3 else np.nan  # stale tail
        a = one.allocate_tracked(v, B, hi, pref, u1, 2, 0.02, 0.03)
        b = two.allocate_tracked(v2, B, hi, pref, u2, 2, 0.02, 0.03, v_tail=v[2:].copy())
        statuses.add(a[0])
        assert np.array(a).tobytes() == np.array(b).tobytes(), k
        assert v2.tobytes() == v.tobytes() and u2.tobytes() == u1.tobytes(), k
        assert one._wsx.tobytes() == two._wsx.tobytes(), k
    assert len(statuses) >= 2  # a solved step and the invalid input at least
    assert one.stats.counts == two.stats.counts
