"""The roll-sideslip-yaw fault predictor (``synthesis/lateral_objective.py``): the coupled
loop's exact ISE against a time simulation of the same chain built independently with
python-control (roll loop, lateral velocity, fin moment, yaw loop in series), and the
coupling's direction (a roll moment alone turns the nose)."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.synthesis.fault_objective import (
    PAPER_CASES,
    disturbance_loop,
    ppid_controller,
    step_ise,
)
from vtolftc.synthesis.lateral_objective import (
    lateral_coefficients,
    lateral_fault_loop,
    lateral_yaw_rmse,
)
from vtolftc.synthesis.robust import design_plant

ROLL = {"kp_angle": 2.6, "kp_rate": 2.0, "ki_rate": 4.0, "kd_rate": 0.05, "tf_rate_s": 0.05}
YAW = {"kp_angle": 2.0, "kp_rate": 3.2, "ki_rate": 2.0, "kd_rate": 0.03, "tf_rate_s": 0.2}


def _brute(af, v, d_roll, d_yaw, horizon):  # type: ignore[no-untyped-def]
    """ISE of psi by python-control's series/parallel interconnection and a simulation."""
    Gr, Gy = design_plant(af, "roll", v, 0.1), design_plant(af, "yaw", v, 0.05)
    roll = ct.ss(*disturbance_loop(Gr, ppid_controller(ROLL)))
    yaw = ct.ss(*disturbance_loop(Gy, ppid_controller(YAW)))
    y_v, n_v = lateral_coefficients(af, v)
    g = af.gravity_m_s2
    lateral = ct.ss([[y_v]], [[g]], [[n_v]], [[0.0]])       # phi -> N_beta
    chain = ct.series(ct.series(ct.ss([], [], [], [[d_roll]]), roll), lateral)
    total = ct.series(ct.parallel(chain, ct.ss([], [], [], [[d_yaw]])), yaw)
    t = np.linspace(0.0, horizon, 60001)
    y = np.asarray(ct.forced_response(total, t, np.ones_like(t)).outputs).reshape(-1)
    return float(np.trapezoid(y**2, t)), (Gr, Gy)


@pytest.mark.parametrize(("v", "d_roll", "d_yaw"), [(2.6, 3.1, -0.12), (7.2, -2.0, 0.3)])
def test_lateral_loop_ise_matches_python_control(v: float, d_roll: float, d_yaw: float,
                                                 ) -> None:
    af = load_airframe()
    want, (Gr, Gy) = _brute(af, v, d_roll, d_yaw, 6.0)
    sys = lateral_fault_loop(af, v, Gr, ppid_controller(ROLL), Gy, ppid_controller(YAW),
                             d_roll, d_yaw)
    assert step_ise(sys, 1.0, 6.0) == pytest.approx(want, rel=2e-3)


def test_a_roll_moment_alone_turns_the_nose_and_more_with_a_weaker_roll_loop() -> None:
    af = load_airframe()
    Gr, Gy = design_plant(af, "roll", 4.9, 0.0), design_plant(af, "yaw", 4.9, 0.0)
    Ky = ppid_controller(YAW)
    strong = step_ise(lateral_fault_loop(af, 4.9, Gr, ppid_controller(ROLL), Gy, Ky, 3.0,
                                         0.0), 1.0, 6.0)
    weak_gains = {**ROLL, "kp_angle": 0.5 * ROLL["kp_angle"], "ki_rate": 0.25 * ROLL["ki_rate"]}
    weak = step_ise(lateral_fault_loop(af, 4.9, Gr, ppid_controller(weak_gains), Gy, Ky, 3.0,
                                       0.0), 1.0, 6.0)
    assert 0.0 < strong < weak
    # and the RMSE over a case is finite and positive
    r = lateral_yaw_rmse(af, lambda v: ppid_controller(ROLL), lambda v: ppid_controller(YAW),
                         PAPER_CASES["1"])
    assert 0.0 < r < np.inf
