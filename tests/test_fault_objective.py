"""The fault-response predictor (``synthesis/fault_objective.py``): its exact ISE against a
brute-force time simulation of the same linear closed loop (``control.forced_response``), the
closed loop against python-control's own feedback interconnection, and the fault moment's
signs against the actuator sign table of README."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.synthesis.fault_objective import (
    PAPER_CASES,
    disturbance_loop,
    fault_gamma,
    fault_moment,
    lqr_controller,
    ppid_controller,
    predicted_rmse,
    step_ise,
)
from vtolftc.synthesis.robust import design_plant

GAINS = {"kp_angle": 2.4, "kp_rate": 0.6, "ki_rate": 0.9, "kd_rate": 0.01,
         "tf_rate_s": 0.02}


def _brute_ise(sys: tuple, d: float, horizon: float) -> float:
    t = np.linspace(0.0, horizon, 60001)
    r = ct.forced_response(ct.ss(*sys), t, np.full_like(t, d))
    y = np.asarray(r.outputs).reshape(-1)
    return float(np.trapezoid(y**2, t))


@pytest.mark.parametrize(("axis", "v", "gamma"), [("roll", 3.6, 0.1), ("pitch", 7.6, 0.0),
                                                  ("yaw", 9.2, 0.3)])
def test_step_ise_matches_a_time_simulation_ppid(axis: str, v: float, gamma: float) -> None:
    af = load_airframe()
    cl = disturbance_loop(design_plant(af, axis, v, gamma), ppid_controller(GAINS))
    for horizon in (0.7, 4.0):
        want = _brute_ise(cl, 1.7, horizon)
        assert step_ise(cl, 1.7, horizon) == pytest.approx(want, rel=2e-4)


def test_step_ise_matches_a_time_simulation_lqr_and_grows_as_d_squared() -> None:
    af = load_airframe()
    cl = disturbance_loop(design_plant(af, "roll", 0.0), lqr_controller(14.1, 20.8, 8.29))
    want = _brute_ise(cl, -2.0, 6.0)
    got = step_ise(cl, -2.0, 6.0)
    assert got == pytest.approx(want, rel=2e-4)
    assert step_ise(cl, -4.0, 6.0) == pytest.approx(4.0 * got, rel=1e-9)


def test_disturbance_loop_is_python_controls_feedback() -> None:
    af = load_airframe()
    G = design_plant(af, "pitch", 5.0)
    for K in (ppid_controller(GAINS), lqr_controller(14.1, 20.2, 7.39)):
        ref = ct.feedback(G, ct.ss(*K), sign=+1)     # u = d + K y: K carries the minus sign
        w = np.logspace(-2, 2, 30)
        want = ref(1j * w)[1, 0]
        cl = ct.ss(*disturbance_loop(G, K))
        np.testing.assert_allclose(np.squeeze(cl(1j * w)), want, rtol=1e-8)


def test_fault_moment_signs_follow_the_actuator_table() -> None:
    af = load_airframe()
    # rotor 2b: rear left, cw: thrust gives roll +, pitch -, yaw -; losing it the opposite
    assert fault_moment(af, "roll", 3.6, {"rotor_2b": 0.5}) < 0
    assert fault_moment(af, "pitch", 3.6, {"rotor_2b": 0.5}) > 0
    assert fault_moment(af, "yaw", 3.6, {"rotor_2b": 0.5}) > 0
    # linear in the loss, zero without a rotor fault
    assert fault_moment(af, "roll", 3.6, {"rotor_2b": 1.0}) == pytest.approx(
        2.0 * fault_moment(af, "roll", 3.6, {"rotor_2b": 0.5}))
    assert fault_moment(af, "roll", 3.6, {"elevator": 0.2}) == 0.0
    assert 0.0 < fault_gamma(af, "roll", 3.6, PAPER_CASES["1"].losses) < 0.3


def test_predicted_rmse_ranks_a_loop_without_integral_action_last() -> None:
    af = load_airframe()
    good = predicted_rmse(af, "roll", lambda v: ppid_controller(GAINS), PAPER_CASES["1"])
    no_int = dict(GAINS, ki_rate=1e-6)
    bad = predicted_rmse(af, "roll", lambda v: ppid_controller(no_int), PAPER_CASES["1"])
    assert 0.0 < good < bad


@pytest.mark.slow
def test_flown_case_airspeeds_are_the_flights_airspeeds_after_the_fault() -> None:
    """FLOWN_CASE_AIRSPEEDS against the in-process flights of case 1 and 2 (shipped robust
    SHIF): the airspeed at 22.5, 23.5, 24.5 and 25.5 s, within 0.4 m/s; and the fault acts
    below the first of them (at 22.0 s, under 2 m/s)."""
    from vtolftc.runners.scenario import paper_scenario, run_scenario
    from vtolftc.synthesis.fault_objective import FLOWN_CASE_AIRSPEEDS, paper_cases

    class Airspeeds:
        def __init__(self) -> None:
            self.rows: list[tuple[float, float]] = []

        def on_start(self, info: dict) -> None:
            pass

        def on_event(self, t: int, kind: str, text: str) -> None:
            pass

        def on_finish(self, m: dict) -> None:
            pass

        def on_sample(self, s) -> None:  # type: ignore[no-untyped-def]
            self.rows.append((s.time_usec * 1e-6, s.status.airspeed_m_s))

    for case in (1, 2):
        obs = Airspeeds()
        run_scenario(paper_scenario(case, duration_s=26.0), "shif", observers=[obs])
        t, v = np.array(obs.rows).T
        flown = np.interp([22.5, 23.5, 24.5, 25.5], t, v)
        assert flown == pytest.approx(FLOWN_CASE_AIRSPEEDS, abs=0.4)
        assert float(np.interp(22.0, t, v)) < 2.0
        assert paper_cases(FLOWN_CASE_AIRSPEEDS)[str(case)].airspeeds_m_s == \
            FLOWN_CASE_AIRSPEEDS
