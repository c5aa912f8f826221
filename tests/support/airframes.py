"""Hypothesis strategy: physically consistent dual-system VTOL airframe documents.

Each drawn document is what :func:`vtolftc.airframe.loader.airframe_from_dict` reads (the
parsed form of an airframe TOML file). It is built from scaling laws around DS-1
(``airframe/ds1.toml``), not from independent random numbers, so that the aircraft is one
that a designer could have drawn:

- mass ``m`` in [2, 30] kg; wing loading ``W/S = 129 N/m^2 * (m / 12.5 kg)^(1/3) * f``,
  ``f`` in [0.8, 1.2] (square-cube law: DS-1 has 129 N/m^2 at 12.5 kg), so the stall speed
  grows from about 9 m/s (2 kg) to about 15 m/s (30 kg);
- span from an aspect ratio in [6, 12], kept within [1.5, 5] m (the interval of spans that
  satisfies both is never empty over these masses and wing loadings); chord ``S / b``;
- DS-1's dimensionless aerodynamics, with the finite-wing lift slope of the drawn aspect ratio
  (Helmbold) and DS-1's dimensionless damping / stiffness tables, their airspeed axis scaled by
  the stall speed over DS-1's (12.7 m/s);
- 4, 6 or 8 lift rotors on two or four booms (front / rear, the 6-rotor layout with a middle
  rotor as HX-6), booms at fractions of the semi-span, arms at fractions of the span;
  alternating spins so that the reaction torques cancel in hover (as many cw as ccw, mirror
  images opposite); each rotor's maximum thrust from the hover thrust-to-weight ``T/W`` in
  [1.5, 3]; propeller diameter from a disk loading in [60, 150] N/m^2 at hover; reaction torque
  ``0.035 D`` per newton (DS-1: 0.016 m for its 18 inch propeller); motor time constant
  growing with the diameter;
- inertias of a mass distribution: motors and propellers (12 % of the mass) at the rotor
  positions, the wing (15 %) spread uniformly along the span, the pushers (4 %) at theirs,
  the rest a solid fuselage box (length 0.5 b, width and height 0.08 b);
- one or two pushers whose total static thrust is 2.2-3.2 times the largest level-flight drag
  (transition end or cruise) over their thrust fall-off with airspeed (DS-1: 2.5);
- one or two ailerons and rudders; landing gear scaled with the span, its spring and dampers
  with the mass (the same static deflection as DS-1).

Units SI; angles in degrees (a document is a file's parsed form). Body FRD at the CG.
"""

from __future__ import annotations

import math
from typing import Any

from hypothesis import strategies as st

__all__ = ["MASS_RANGE_KG", "N_LIFT_ROTORS", "SPAN_RANGE_M", "TW_RANGE", "airframe_documents",
           "hover_thrust_to_weight"]

MASS_RANGE_KG = (2.0, 30.0)
"""Mass range of the generated airframes [kg]."""
SPAN_RANGE_M = (1.5, 5.0)
"""Wing span range [m]."""
TW_RANGE = (1.5, 3.0)
"""Hover thrust-to-weight range of the lift rotors [-]."""
N_LIFT_ROTORS = (4, 6, 8)
"""Lift-rotor counts drawn."""
ASPECT_RATIO_RANGE = (6.0, 12.0)
"""Aspect-ratio range the span is drawn from (then kept within :data:`SPAN_RANGE_M`)."""

_RHO = 1.225
_G = 9.80665
_DS1_MASS_KG = 12.5
_DS1_WING_LOADING_N_M2 = 12.5 * _G / 0.95
_DS1_STALL_M_S = 12.7
_CL0, _CL_MAX, _CD0, _OSWALD = 0.59, 1.30, 0.045, 0.8
_PUSHER_ZERO_THRUST_M_S = 45.0

# DS-1's dimensionless derivative tables (ds1.toml [derivatives]).
_DS1_AXIS = (0.0, 1.0, 2.0, 4.0, 7.0, 10.0, 13.0, 18.0)
_DS1_TABLES = {
    "C_lp": [-0.306, -0.3213, -0.3417, -0.3774, -0.4233, -0.459, -0.4845, -0.51],
    "C_mq": [-22.92, -24.066, -25.594, -28.268, -31.706, -34.38, -36.29, -38.2],
    "C_malpha": [-1.644, -1.7262, -1.8358, -2.0276, -2.2742, -2.466, -2.603, -2.74],
    "C_nr": [-0.057, -0.05985, -0.06365, -0.0703, -0.07885, -0.0855, -0.09025, -0.095],
    "C_nbeta": [0.0438, 0.04599, 0.04891, 0.05402, 0.06059, 0.0657, 0.06935, 0.073],
}

# DS-1's dimensionless wing coefficients other than the lift slope (ds1.toml [wing]).
_WING_COEFFS = {
    "CL0": _CL0, "CL_max": _CL_MAX, "stall_rounding_deg": 3.0, "post_stall_blend_per_rad": 50.0,
    "CL_q": 7.95, "CL_de_per_rad": 0.13, "CD0": _CD0, "oswald_efficiency": _OSWALD,
    "CY_beta": -0.98, "CY_p": 0.0, "CY_r": 0.0, "CY_da": 0.075, "CY_dr": 0.19,
    "Cl_beta": -0.13, "Cl_r": 0.25, "Cl_da": 0.17, "Cl_dr": 0.0024, "Cm0": 0.08,
    "Cm_de": -0.99, "Cn_p": -0.069, "Cn_da": -0.011, "Cn_dr": -0.069,
    "moment_angle_linear_deg": 15.0, "moment_angle_saturation_deg": 30.0,
}


def _unit(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def _layout(n: int, b: float, arm_f: float, arm_r: float, y_in: float, y_out: float,
            z: float) -> list[tuple[str, float, float, str]]:
    """Lift-rotor (name, x, y, spin) on booms; spins alternate so yaw torques cancel.

    Boom ``k`` (left to right) carries a front rotor ``ka`` at ``x = arm_f`` and a rear one
    ``kb`` at ``x = -arm_r`` (plus a middle ``km`` at x = 0.1 (arm_f - arm_r) for 6 rotors).
    """
    del b, z
    if n == 8:  # DS-1: four booms, cw/ccw alternating along and across
        booms = ((-y_out, "cw"), (-y_in, "ccw"), (y_in, "cw"), (y_out, "ccw"))
        out = []
        for k, (y, front) in enumerate(booms, start=1):
            rear = "ccw" if front == "cw" else "cw"
            out += [(f"{k}a", arm_f, y, front), (f"{k}b", -arm_r, y, rear)]
        return out
    if n == 4:  # quadplane: two booms, diagonal rotors turn the same way
        return [("1a", arm_f, -y_out, "cw"), ("1b", -arm_r, -y_out, "ccw"),
                ("2a", arm_f, y_out, "ccw"), ("2b", -arm_r, y_out, "cw")]
    x_mid = 0.1 * (arm_f - arm_r)  # 6: two booms of three (HX-6)
    return [("1a", arm_f, -y_out, "cw"), ("1m", x_mid, -y_out, "ccw"),
            ("1b", -arm_r, -y_out, "cw"), ("2a", arm_f, y_out, "ccw"),
            ("2m", x_mid, y_out, "cw"), ("2b", -arm_r, y_out, "ccw")]


def _helmbold(ar: float) -> float:
    """Finite-wing lift slope [1/rad] of aspect ratio ``ar`` (Helmbold's formula)."""
    return 2.0 * math.pi * ar / (2.0 + math.sqrt(ar * ar + 4.0))


@st.composite
def airframe_documents(draw: st.DrawFn) -> dict[str, Any]:
    """Draw one airframe document (see the module docstring for the scaling laws).

    Returns
    -------
    dict
        A parsed airframe file: ``airframe_from_dict(doc)`` loads it. Extra information for
        the tests is under no key of the document (nothing the loader would refuse).
    """
    m = draw(_unit(*MASS_RANGE_KG))
    weight = m * _G
    wl = _DS1_WING_LOADING_N_M2 * (m / _DS1_MASS_KG) ** (1.0 / 3.0) * draw(_unit(0.8, 1.2))
    area = weight / wl
    b_lo = max(SPAN_RANGE_M[0], math.sqrt(ASPECT_RATIO_RANGE[0] * area))
    b_hi = min(SPAN_RANGE_M[1], math.sqrt(ASPECT_RATIO_RANGE[1] * area))
    span = b_lo + (b_hi - b_lo) * draw(_unit(0.0, 1.0))
    ar = span * span / area
    chord = area / span
    stall = math.sqrt(weight / (0.5 * _RHO * area * _CL_MAX))

    # lift rotors
    n = draw(st.sampled_from(N_LIFT_ROTORS))
    tw = draw(_unit(*TW_RANGE))
    t_max = tw * weight / n
    disk_loading = draw(_unit(60.0, 150.0))
    diameter = math.sqrt(4.0 * (weight / n) / (math.pi * disk_loading))
    semi = 0.5 * span
    y_out = semi * draw(_unit(0.55, 0.75))
    y_in = semi * draw(_unit(0.22, 0.32))
    arm = span * draw(_unit(0.18, 0.26))
    cg_shift = draw(_unit(-0.05, 0.05))  # CG ahead (+) of the middle of the rotor arms
    arm_f, arm_r = arm * (1.0 - cg_shift), arm * (1.0 + cg_shift)
    z_rot = -0.035 * span
    # keep neighbouring discs apart: the outer booms clear the inner ones by a diameter
    y_out = max(y_out, y_in + 1.05 * diameter) if n == 8 else max(y_out, 0.55 * diameter)
    layout = _layout(n, span, arm_f, arm_r, y_in, y_out, z_rot)
    tau_rotor = min(0.12, max(0.03, 0.05 * diameter / 0.457))

    # pushers: thrust from the largest level-flight drag (transition end, cruise)
    n_push = draw(st.sampled_from((1, 2)))
    q_s = 0.5 * _RHO * area

    def drag(v: float) -> float:
        cl = weight / (q_s * v * v)
        return q_s * v * v * (_CD0 + cl * cl / (math.pi * _OSWALD * ar))

    need = max(drag(1.05 * stall) / (1.0 - 1.05 * stall / _PUSHER_ZERO_THRUST_M_S),
               drag(1.4 * stall) / (1.0 - 1.4 * stall / _PUSHER_ZERO_THRUST_M_S))
    push_total = need * draw(_unit(2.2, 3.2))
    push_y = 0.14 * span if n_push == 2 else 0.0
    push_x = -1.15 * arm_r
    pushers = ([("left", push_x, -push_y, "cw"), ("right", push_x, push_y, "ccw")]
               if n_push == 2 else [("center", push_x, 0.0, "cw")])

    # inertias of the mass distribution (body FRD about the CG)
    m_rot, m_wing, m_push = 0.12 * m, 0.15 * m, 0.04 * m
    m_fus = m - m_rot - m_wing - m_push
    lf, wf, hf = 0.5 * span, 0.08 * span, 0.08 * span
    jx = m_wing * span ** 2 / 12.0 + m_fus * (wf ** 2 + hf ** 2) / 12.0
    jy = m_fus * (lf ** 2 + hf ** 2) / 12.0
    jz = m_wing * span ** 2 / 12.0 + m_fus * (lf ** 2 + wf ** 2) / 12.0
    for _, x, y, _ in layout:
        mi = m_rot / n
        jx += mi * (y * y + z_rot * z_rot)
        jy += mi * (x * x + z_rot * z_rot)
        jz += mi * (x * x + y * y)
    for _, x, y, _ in pushers:
        mi = m_push / n_push
        jx += mi * y * y
        jy += mi * x * x
        jz += mi * (x * x + y * y)

    scale = stall / _DS1_STALL_M_S
    gear_x, gear_y, gear_z = 0.155 * span, 0.19 * span, 0.103 * span
    k_gear = 4000.0 * m / _DS1_MASS_KG
    doc: dict[str, Any] = {
        "airframe": {
            "name": f"GEN-{n}{'+' + str(n_push)} {m:.1f} kg {span:.2f} m",
            "description": f"generated dual-system VTOL: {n} lift rotors, {n_push} pusher(s), "
                           f"T/W {tw:.2f}, AR {ar:.1f}",
        },
        "environment": {"air_density_kg_m3": _RHO, "gravity_m_s2": _G},
        "mass": {"mass_kg": m, "Jx_kg_m2": jx, "Jy_kg_m2": jy, "Jz_kg_m2": jz,
                 "Jxz_kg_m2": 0.0},
        "wing": {"area_m2": area, "span_m": span, "chord_m": chord,
                 "CL_alpha_per_rad": _helmbold(ar), **_WING_COEFFS},
        "derivatives": {"airspeed_m_s": [v * scale for v in _DS1_AXIS],
                        **{k: list(v) for k, v in _DS1_TABLES.items()}},
        "lift_rotors": {
            "max_thrust_N": t_max, "torque_to_thrust_m": 0.035 * diameter,
            "time_constant_s": tau_rotor, "rate_limit_per_s": 10.0,
            "zero_thrust_axial_speed_m_s": 40.0,
            "rotor": [{"name": name, "x_m": x, "y_m": y, "z_m": z_rot, "spin": spin}
                      for name, x, y, spin in layout],
        },
        "pushers": {
            "max_thrust_N": push_total / n_push, "torque_to_thrust_m": 0.012 * span / 2.9,
            "time_constant_s": 0.05, "rate_limit_per_s": 10.0,
            "zero_thrust_axial_speed_m_s": _PUSHER_ZERO_THRUST_M_S,
            "rotor": [{"name": name, "x_m": x, "y_m": y, "z_m": 0.0, "spin": spin}
                      for name, x, y, spin in pushers],
        },
        "surfaces": {"ailerons": draw(st.sampled_from((1, 2))),
                     "rudders": draw(st.sampled_from((1, 2))),
                     "max_deflection_deg": 25.0, "time_constant_s": 0.05,
                     "rate_limit_deg_s": 350.0},
        "landing_gear": {
            "points_m": [[gear_x, -gear_y, gear_z], [gear_x, gear_y, gear_z],
                         [-gear_x, -gear_y, gear_z], [-gear_x, gear_y, gear_z]],
            "stiffness_N_m": k_gear, "damping_N_s_m": 300.0 * m / _DS1_MASS_KG,
            "friction_N_s_m": 150.0 * m / _DS1_MASS_KG, "friction_coefficient": 0.6,
        },
    }
    return doc


def hover_thrust_to_weight(doc: dict[str, Any]) -> float:
    """Total lift-rotor static thrust over the weight of a document [-]."""
    lr = doc["lift_rotors"]
    return lr["max_thrust_N"] * len(lr["rotor"]) / (doc["mass"]["mass_kg"] * _G)
