"""Numerical linearisation of the 6-DOF vehicle against the paper's closed forms (eq 1-3).

Roll: p' = Mx^p / Jx p + ...,  Mx^p = rho V S b^2 C_lp(V) / 4
Pitch: q' = (My^q q + My^alpha theta) / Jy,  My^q = rho V S c^2 C_mq / 4,
       My^alpha = qbar S c C_malpha
Yaw: r' = (Mz^r r - qbar S b C_nbeta psi) / Jz  (velocity held: beta = -psi)
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtolftc.firmware_sim.vehicle.linearize import linearize
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.trim import trim_hover, trim_level_flight


def _closed_form(af, V):
    w = af.wing
    d = af.derivatives.at(V)
    rho = af.air_density_kg_m3
    qbar = 0.5 * rho * V * V
    J = np.diag(af.inertia_kg_m2)
    return {
        ("p", "p"): rho * V * w.area_m2 * w.span_m**2 * d["C_lp"] / 4 / J[0],
        ("q", "q"): rho * V * w.area_m2 * w.chord_m**2 * d["C_mq"] / 4 / J[1],
        ("q", "dtheta"): qbar * w.area_m2 * w.chord_m * d["C_malpha"] / J[1],
        ("r", "r"): rho * V * w.area_m2 * w.span_m**2 * d["C_nr"] / 4 / J[2],
        ("r", "dpsi"): -qbar * w.area_m2 * w.span_m * d["C_nbeta"] / J[2],
    }


@pytest.mark.parametrize(("V", "pitch"), [(4.0, 0.0), (7.0, 0.0), (10.0, 0.0), (13.0, 0.0),
                                          (13.0, None), (18.0, None)])
def test_linearisation_matches_the_control_oriented_models(ds1, V, pitch):
    tp = trim_level_flight(ds1, V, pitch_rad=pitch)
    lm = linearize(Vehicle(ds1), tp.state)
    for (row, col), expected in _closed_form(ds1, V).items():
        # Yaw stiffness: the body-axis yaw perturbation changes beta by cos(alpha) only.
        tol = 0.015 if col == "dpsi" else 1e-5
        assert lm.a(row, col) == pytest.approx(expected, rel=tol), (row, col)
    # Control moments scale with dynamic pressure: B(q, elevator) = qbar S c Cm_de dmax / Jy.
    qbar = 0.5 * ds1.air_density_kg_m3 * V * V
    b_el = qbar * ds1.wing.area_m2 * ds1.wing.chord_m * ds1.wing.Cm_de * \
        ds1.surfaces.max_deflection_rad / ds1.inertia_kg_m2[1, 1]
    assert lm.b("q", "elevator") == pytest.approx(b_el * math.cos(0.0), rel=1e-5)


def test_hover_linearisation_is_a_pure_inertia(ds1):
    tp = trim_hover(ds1)
    lm = linearize(Vehicle(ds1), tp.state)
    for row in ("p", "q", "r"):
        for col in ("dphi", "dtheta", "dpsi", "p", "q", "r"):
            assert abs(lm.a(row, col)) < 1e-6
    # Rotor 1a (front left): roll right and pitch up, torque = arm x thrust / inertia.
    r = ds1.lift_rotors[0]
    assert lm.b("p", "rotor_1a") == pytest.approx(-r.position_m[1] * 35.0 / 1.6, rel=1e-6)
    assert lm.b("q", "rotor_1a") == pytest.approx(r.position_m[0] * 35.0 / 1.3, rel=1e-6)
    # Attitude kinematics: d(angle)/dt = rate.
    assert lm.a("dtheta", "q") == pytest.approx(1.0)
    # Gravity tilts the thrust: a roll angle accelerates east.
    assert lm.a("ve", "dphi") == pytest.approx(ds1.gravity_m_s2, rel=1e-6)
