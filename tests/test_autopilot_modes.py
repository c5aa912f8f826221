"""Mode machine, commands, parameters and status of the autopilot (synthetic navigation data,
no vehicle)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.protocols import protocol_mismatches

from vtolftc.firmware_sim.autopilot.autopilot import (
    CMD_COMPONENT_ARM_DISARM,
    CMD_DO_SET_MODE,
    CMD_DO_VTOL_TRANSITION,
    CMD_NAV_LAND,
    CMD_NAV_TAKEOFF,
    Autopilot,
)
from vtolftc.firmware_sim.autopilot.interface import (
    AutopilotAPI,
    CommandResult,
    FlightMode,
    LandedState,
    NavState,
    ParamError,
    ParamType,
    VtolState,
)
from vtolftc.firmware_sim.autopilot.modes import ModeMachine, px4_custom_mode

NAN = float("nan")
A = CommandResult.ACCEPTED
D = CommandResult.DENIED


@pytest.fixture(scope="module")
def gains_dir(hand_gains):
    return hand_gains


def nav(t_s: float, alt: float = 0.29, airspeed: float = 0.0, vn: float = 0.0) -> NavState:
    return NavState(round(t_s * 1e6), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3),
                    np.array([0.0, 0.0, -alt]), np.array([vn, 0.0, 0.0]), airspeed)


def cmd(ap, cid, *p):
    return ap.command(cid, list(p) + [NAN] * (7 - len(p)))


@pytest.fixture
def ap(ds1, gains_dir):
    return Autopilot(ds1, controller="shif", gains_dir=gains_dir)


def test_autopilot_implements_the_api(ap):
    assert isinstance(ap, AutopilotAPI)
    assert protocol_mismatches(ap, AutopilotAPI) == []


def test_the_protocol_check_sees_a_wrong_signature():
    class Wrong:
        def step(self, state, extra): ...

    assert any(m.startswith("step") for m in protocol_mismatches(Wrong(), AutopilotAPI))
    assert any("missing" in m for m in protocol_mismatches(Wrong(), AutopilotAPI))


def test_ground_commands_and_denials(ap):
    # nothing known yet: arming denied
    assert cmd(ap, CMD_COMPONENT_ARM_DISARM, 1.0) == D
    u = ap.step(nav(0.0))
    assert u.shape == (15,) and np.all(u == 0.0)            # disarmed: everything off
    assert cmd(ap, CMD_NAV_TAKEOFF) == D                     # takeoff while disarmed
    assert cmd(ap, CMD_DO_VTOL_TRANSITION, 4.0) == D         # transition while disarmed
    assert cmd(ap, 12345) == CommandResult.UNSUPPORTED
    assert cmd(ap, CMD_COMPONENT_ARM_DISARM, 7.0) == D       # not 0 or 1
    assert cmd(ap, CMD_COMPONENT_ARM_DISARM, 1.0) == A
    st = ap.status()
    assert st.armed and st.mode == FlightMode.IDLE and st.landed_state == LandedState.ON_GROUND
    u = ap.step(nav(0.004))
    assert np.all(u[:8] == pytest.approx(0.05)) and np.all(u[8:] == 0.0)   # armed idle
    assert cmd(ap, CMD_DO_VTOL_TRANSITION, 4.0) == D         # on the ground
    assert cmd(ap, CMD_NAV_LAND) == D                        # on the ground
    assert cmd(ap, CMD_COMPONENT_ARM_DISARM, 0.0) == A       # disarm on the ground
    assert not ap.status().armed


def test_takeoff_default_altitude_param_and_flight_sequence(ap):
    ap.step(nav(0.0))
    ap.params.set("MIS_TAKEOFF_ALT", 12.0)                   # parameter change takes effect
    assert cmd(ap, CMD_COMPONENT_ARM_DISARM, 1.0) == A
    assert cmd(ap, CMD_NAV_TAKEOFF, NAN, NAN, NAN, NAN, NAN, NAN, NAN) == A
    st = ap.status()
    assert st.mode == FlightMode.TAKEOFF and st.altitude_ref_m == 12.0
    assert st.landed_state == LandedState.TAKEOFF and st.vtol_state == VtolState.MC
    u = ap.step(nav(0.004))
    assert np.all(u[:8] == pytest.approx(0.04))               # rotor rate limit 10/s
    for k in range(2, 30):
        u = ap.step(nav(0.004 * k))
    assert np.all(u[:8] > 0.5)                                # climbing
    assert cmd(ap, CMD_DO_VTOL_TRANSITION, 4.0) == D          # not during the climb
    # in-air disarm needs the force magic
    assert cmd(ap, CMD_COMPONENT_ARM_DISARM, 0.0) == D
    ap.step(nav(0.120, alt=11.8))                             # within 0.5 m -> hover
    assert ap.status().mode == FlightMode.HOVER
    assert ap.status().landed_state == LandedState.IN_AIR
    assert cmd(ap, CMD_DO_VTOL_TRANSITION, 2.0) == D          # bad param1
    assert cmd(ap, CMD_DO_VTOL_TRANSITION, 4.0) == A
    ap.step(nav(0.124, alt=12.0, airspeed=10.0, vn=10.0))
    st = ap.status()
    assert st.mode == FlightMode.FRONT_TRANSITION and st.vtol_state == VtolState.TRANSITION_TO_FW
    np.testing.assert_allclose(st.attitude_ref_rad[:2], 0.0)  # roll 0, pitch 0 (paper)
    assert st.virtual_command[1] > 0.0                        # pusher ramping up
    ap.params.set("VT_ARSP_TRANS", 9.5)                       # takes effect at once
    ap.step(nav(0.128, alt=12.0, airspeed=10.0, vn=10.0))
    st = ap.status()
    assert st.mode == FlightMode.FIXED_WING and st.vtol_state == VtolState.FW
    assert "transition complete" in st.message
    assert cmd(ap, CMD_DO_VTOL_TRANSITION, 4.0) == A          # already there
    assert cmd(ap, CMD_DO_VTOL_TRANSITION, 3.0) == A
    assert ap.status().mode == FlightMode.BACK_TRANSITION
    ap.step(nav(0.132, alt=12.0, airspeed=4.0, vn=4.0))       # slow enough -> hover
    assert ap.status().mode == FlightMode.HOVER
    assert cmd(ap, CMD_NAV_LAND) == A
    assert ap.status().mode == FlightMode.LAND
    assert ap.status().landed_state == LandedState.LANDING
    t = 0.136
    while t < 2.2:                                            # on the ground, still: landed
        ap.step(nav(t))
        t += 0.004
    st = ap.status()
    assert st.mode == FlightMode.IDLE and st.armed            # landed, rotors at idle
    assert st.landed_state == LandedState.ON_GROUND
    assert np.all(st.actuator_commands[:8] == pytest.approx(0.05))
    landed_ms = ap.arming.landing_ms
    assert 1100 < landed_ms < 1200                            # 1 s still on the ground
    while ap.status().armed:                                  # COM_DISARM_LAND (2 s) later
        ap.step(nav(t))
        t += 0.004
    assert t * 1e3 - landed_ms == pytest.approx(2000.0, abs=10.0)
    st = ap.status()
    assert st.mode == FlightMode.IDLE and st.message == "Disarmed by landing"


def test_forced_disarm_in_air(ap):
    ap.step(nav(0.0))
    cmd(ap, CMD_COMPONENT_ARM_DISARM, 1.0)
    cmd(ap, CMD_NAV_TAKEOFF)
    assert cmd(ap, CMD_COMPONENT_ARM_DISARM, 0.0, 21196.0) == A
    assert not ap.status().armed and np.all(ap.step(nav(0.004, alt=5.0)) == 0.0)


def test_set_mode(ap):
    ap.step(nav(0.0))
    assert cmd(ap, CMD_DO_SET_MODE, 1.0, 4.0, 2.0) == D       # AUTO.TAKEOFF while disarmed
    cmd(ap, CMD_COMPONENT_ARM_DISARM, 1.0)
    assert cmd(ap, CMD_DO_SET_MODE, 1.0, 4.0, 2.0) == A
    assert ap.status().mode == FlightMode.TAKEOFF
    assert cmd(ap, CMD_DO_SET_MODE, 1.0, 3.0) == A            # POSCTL: hold
    assert ap.status().mode == FlightMode.HOVER
    assert cmd(ap, CMD_DO_SET_MODE, 1.0, 6.0) == D            # OFFBOARD: not offered
    assert cmd(ap, CMD_DO_SET_MODE, NAN, NAN) == D
    assert cmd(ap, CMD_DO_SET_MODE, 1.0, 4.0, 6.0) == A       # AUTO.LAND
    assert ap.status().mode == FlightMode.LAND
    assert px4_custom_mode(FlightMode.LAND) == (4 << 16) | (6 << 24)


def test_parameters(ap):
    p = ap.params
    for name in ("SYS_FAILURE_EN", "MIS_TAKEOFF_ALT", "VT_ARSP_TRANS", "VT_TRANS_TMOUT",
                 "FW_AIRSPD_TRIM", "MPC_Z_P", "MPC_Z_VEL_P_ACC", "MPC_Z_VEL_I_ACC"):
        assert name in p
    f = p.by_index(p.index("SYS_FAILURE_EN"))
    assert f.type == ParamType.INT32 and f.value == 0
    assert p.get("VT_ARSP_TRANS") == 13.0 and p.get("FW_AIRSPD_TRIM") == 18.0
    assert p.get("MIS_TAKEOFF_ALT") == 30.0
    with pytest.raises(ParamError):
        p.set("SYS_FAILURE_EN", 0.5)
    with pytest.raises(ParamError):
        p.set("VT_ARSP_TRANS", -3.0)
    with pytest.raises(ParamError):
        p.set("NO_SUCH_PARAM", 1.0)


def test_mode_machine_quad_chute_and_back_transition():
    m = ModeMachine()
    kw = dict(altitude_m=30.0, takeoff_alt_m=30.0, arsp_trans=13.0, trans_timeout_s=5.0,
              b_trans_arsp=5.0, b_trans_dur_s=20.0, landed=False)
    assert m.arm() == A and m.takeoff() == A
    m.update(0, airspeed_m_s=0.0, **kw)
    assert m.mode == FlightMode.HOVER
    assert m.transition(True) == A and m.mode == FlightMode.FRONT_TRANSITION
    m.update(4_900_000, airspeed_m_s=9.0, **kw)
    assert m.mode == FlightMode.FRONT_TRANSITION
    m.update(5_100_000, airspeed_m_s=9.0, **kw)
    assert m.mode == FlightMode.HOVER
    assert any("quad-chute" in t for _, t in m.events)
    assert m.transition(True) == A
    m.update(6_000_000, airspeed_m_s=13.0, **kw)
    assert m.mode == FlightMode.FIXED_WING
    assert m.land() == A and m.mode == FlightMode.BACK_TRANSITION
    assert m.transition(True) == D                         # not while going back
    m.update(7_000_000, airspeed_m_s=4.0, **kw)
    assert m.mode == FlightMode.LAND                       # land after the back transition
    kw["landed"] = True
    m.update(8_000_000, airspeed_m_s=0.0, **kw)
    assert m.mode == FlightMode.IDLE and m.armed            # the autopilot disarms later


def test_nan_and_garbage_params_do_not_raise(ap):
    ap.step(nav(0.0))
    assert cmd(ap, CMD_COMPONENT_ARM_DISARM, NAN) == D
    assert ap.command(CMD_COMPONENT_ARM_DISARM, ["x"]) == D
    ap.set_home(45.5, 9.15, 122.0)
    assert cmd(ap, CMD_NAV_TAKEOFF, *([NAN] * 6), -5.0) == D  # AMSL: below the ground
    assert math.isfinite(ap.status().altitude_ref_m)


def test_non_finite_navigation_holds_the_last_command(ap):
    ap.step(nav(0.0))
    cmd(ap, CMD_COMPONENT_ARM_DISARM, 1.0)
    cmd(ap, CMD_NAV_TAKEOFF)
    for k in range(1, 20):
        u = ap.step(nav(0.004 * k))
    bad = nav(0.1)
    bad.pos_ned_m[2] = NAN
    u2 = ap.step(bad)
    np.testing.assert_array_equal(u, u2)
    assert ap.status().allocation_status == "invalid navigation data"


def test_update_outside_the_auto_exit_modes_only_advances_the_clock():
    """In every mode outside ``AUTO_EXIT_MODES`` ``ModeMachine.update`` does what ``advance``
    does (the commander calls only that there), whatever its arguments: take-off altitude
    reached, airspeed above every threshold, timeouts passed, landed."""
    import copy
    import itertools

    from vtolftc.firmware_sim.autopilot.interface import FlightMode
    from vtolftc.firmware_sim.autopilot.modes import AUTO_EXIT_MODES, ModeMachine

    args = [dict(altitude_m=h, takeoff_alt_m=30.0, airspeed_m_s=V, arsp_trans=15.0,
                 trans_timeout_s=tt, b_trans_arsp=8.0, b_trans_dur_s=tt, landed=landed)
            for h, V, tt, landed in itertools.product((30.0, 0.0), (0.0, 20.0), (0.0, 1e9),
                                                      (True, False))]
    outside = [m for m in FlightMode if m not in AUTO_EXIT_MODES]
    assert FlightMode.HOVER in outside and FlightMode.FIXED_WING in outside
    for mode, kw in itertools.product(FlightMode, args):
        mm = ModeMachine(mode=mode, armed=True, mode_since_usec=0, now_usec=1000)
        a, b = copy.deepcopy(mm), copy.deepcopy(mm)
        a.update(50_000_000, **kw)
        b.advance(50_000_000)
        if mode in outside:
            assert a == b, (mode, kw)
    # each auto-exit mode does leave by itself with some arguments
    for mode in AUTO_EXIT_MODES:
        left = False
        for kw in args:
            a = ModeMachine(mode=mode, armed=True, now_usec=1000)
            a.update(50_000_000, **kw)
            left |= a.mode != mode
        assert left, mode
