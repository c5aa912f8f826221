"""The failsafe state machine on its own: each failsafe fires exactly past its parameter's
time, with the configured action, and clears on disarm."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.failsafe import (
    MAV_STATE_CRITICAL,
    MAV_STATE_EMERGENCY,
    FailsafeMonitor,
)
from vtolftc.firmware_sim.autopilot.interface import (
    AutopilotStatus,
    FlightMode,
    LandedState,
    NavState,
    ParameterStore,
    VtolState,
)


def _status(mode=FlightMode.HOVER, armed=True) -> AutopilotStatus:
    z = np.zeros(3)
    return AutopilotStatus(0, mode, armed, VtolState.MC, LandedState.IN_AIR, z, z, 0.0, 0.0,
                           np.zeros(5), np.zeros(15), "", "gs-shif")


def _nav(t_us: int, alt: float, roll: float = 0.0, pitch: float = 0.0) -> NavState:
    cr, sr, cp, sp = math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), \
        math.sin(pitch / 2)
    q = np.array([cr * cp, sr * cp, cr * sp, -sr * sp])
    return NavState(t_us, q, np.zeros(3), np.array([0.0, 0.0, -alt]), np.zeros(3), 0.0)


def _check(m: FailsafeMonitor, hil: float = 0.0, gcs: float = 0.5, fw: bool = False):
    return m.check(armed=True, in_air=True, fixed_wing=fw, hil_age_s=hil, gcs_age_s=gcs)


@pytest.mark.parametrize(("act", "action"), [(0, ""), (1, "hold"), (2, "rtl"), (3, "land")])
def test_datalink_loss_fires_after_com_dl_loss_t(act, action):
    ps = ParameterStore()
    m = FailsafeMonitor(ps, realtime=True)
    ps.set("COM_DL_LOSS_T", 3.0)
    ps.set("NAV_DLL_ACT", act)
    assert m.check(armed=True, in_air=True, fixed_wing=False, hil_age_s=0.0,
                   gcs_age_s=math.inf) == []  # never had a ground station: nothing to lose
    assert _check(m, gcs=2.99) == []
    ev = _check(m, gcs=3.01)
    assert len(ev) == 1 and ev[0].name == "datalink" and ev[0].action == action
    assert m.mav_state == MAV_STATE_CRITICAL
    assert _check(m, gcs=5.0) == []  # once
    back = _check(m, gcs=0.2)
    assert back[0].text == "data link regained"
    assert m.mav_state == (MAV_STATE_CRITICAL if action else None)


def test_return_is_rtl_and_land_from_fixed_wing_transitions_back():
    for act, action, text in ((2, "rtl", "return to launch"), (3, "land", "back transition")):
        ps = ParameterStore()
        m = FailsafeMonitor(ps, realtime=True)
        ps.set("NAV_DLL_ACT", act)
        _check(m)
        ev = _check(m, gcs=10.5, fw=True)
        assert ev[0].action == action and text in ev[0].text


def test_hil_loss_lands_in_real_time_reports_in_lockstep():
    ps = ParameterStore()
    m = FailsafeMonitor(ps, realtime=True)
    ps.set("COM_HIL_LOSS_T", 0.5)
    assert _check(m, hil=0.49) == []
    ev = _check(m, hil=0.51)
    assert ev[0].name == "hil" and ev[0].action == "land" and m.mav_state == MAV_STATE_EMERGENCY
    assert _check(m, hil=0.01)[0].text == "sensor/HIL data back"
    assert m.mav_state == MAV_STATE_CRITICAL  # the landing goes on
    ls = FailsafeMonitor(ParameterStore(), realtime=False)
    assert _check(ls, hil=1.4) == []          # the lockstep vehicle repeats every 0.5 s
    ev = _check(ls, hil=1.6)
    assert ev[0].action == "" and ls.mav_state == MAV_STATE_EMERGENCY


def test_attitude_failure_after_the_trigger_time():
    ps = ParameterStore()
    m = FailsafeMonitor(ps, realtime=False)
    st = _status()
    m.on_step(_nav(0, 10.0), st)
    ttri = ps.get("FD_FAIL_R_TTRI")
    fired = None
    for k in range(1, 200):  # 4 ms steps, roll 61 deg from t = 4 ms
        ev = m.on_step(_nav(4000 * k, 10.0, roll=math.radians(61)), st)
        if ev:
            fired = 4000 * k
            assert ev[0].name == "attitude" and "roll 61" in ev[0].text
            break
    assert fired is not None and (fired - 4000) * 1e-6 == pytest.approx(ttri, abs=0.0041)
    assert m.mav_state == MAV_STATE_EMERGENCY
    # 59 deg never fires
    m2 = FailsafeMonitor(ParameterStore(), realtime=False)
    assert not any(m2.on_step(_nav(4000 * k, 10.0, pitch=math.radians(59)), st)
                   for k in range(300))


def test_crash_on_ground_contact_in_flight_then_cleared_by_disarm():
    m = FailsafeMonitor(ParameterStore(), realtime=True)
    st = _status()
    m.on_step(_nav(0, 0.0), _status(FlightMode.IDLE))     # armed on the ground
    assert m.on_step(_nav(4000, 1.0), _status(FlightMode.TAKEOFF)) == []
    assert m.on_step(_nav(8000, 0.3), st) == []           # never above 2 m: not a crash
    m.on_step(_nav(12000, 5.0), st)
    ev = m.on_step(_nav(16000, 0.4), st)
    assert ev[0].name == "crash" and ev[0].action == "disarm"
    assert m.mav_state == MAV_STATE_EMERGENCY
    m.on_step(_nav(20000, 0.0), _status(FlightMode.IDLE, armed=False))
    assert m.mav_state is None
    # landing is not a crash
    m.on_step(_nav(24000, 0.0), _status(FlightMode.IDLE))
    m.on_step(_nav(28000, 5.0), st)
    assert m.on_step(_nav(32000, 0.1), _status(FlightMode.LAND)) == []
