"""Control-oriented attitude models of the paper (eq 1-3), from an airframe file.

For an axis and an airspeed ``V`` (m/s), with ``gamma`` the loss of control effectiveness of
that axis' moment (0 healthy .. 1 lost), the transfer functions from the control moment (N m)
to the body rate (rad/s) are

- roll  (eq 1): G_p(s) = (1 - gamma) / (Jx s - Mx^p(V))
- pitch (eq 2): G_q(s) = (1 - gamma) s / (Jy s^2 - My^q(V) s - My^alpha(V))
- yaw   (eq 3): G_r(s) = (1 - gamma) s / (Jz s^2 - Mz^r(V) s + qbar S b C_nbeta(V))

with Mx^p = rho V S b^2 C_lp / 4, My^q = rho V S c^2 C_mq / 4, My^alpha = qbar S c C_malpha,
Mz^r = rho V S b^2 C_nr / 4 (the yaw stiffness sign follows from beta = -psi with the velocity
held; the paper writes it as -Mz^beta with Mz^beta = -qbar S b C_nbeta). The attitude angle is
the rate integrated: angle(s) = rate(s) / s. These models match a numerical linearisation of
the nonlinear vehicle (``tests/test_linearize.py``, ``tests/test_synthesis_models.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import control as ct
import numpy as np

from vtolftc.airframe.loader import Airframe
from vtolftc.rotation import ATTITUDE_AXES

Axis = Literal["roll", "pitch", "yaw"]
AXES: tuple[Axis, ...] = ATTITUDE_AXES  # type: ignore[assignment]


@dataclass(frozen=True)
class AxisCoefficients:
    """Dimensional coefficients of one axis at one airspeed (SI; body axes FRD).

    Parameters
    ----------
    axis : {"roll", "pitch", "yaw"}
        The axis.
    airspeed_m_s : float
        Airspeed V (m/s).
    inertia : float
        Jx, Jy or Jz (kg m^2).
    damping : float
        Mx^p, My^q or Mz^r (N m s / rad), <= 0.
    stiffness : float
        My^alpha or -qbar S b C_nbeta (N m / rad), <= 0; 0 for roll.
    """

    axis: Axis
    airspeed_m_s: float
    inertia: float
    damping: float     # Mx^p, My^q or Mz^r (N m s / rad), <= 0
    stiffness: float   # My^alpha or -qbar S b C_nbeta (N m / rad), <= 0; 0 for roll


def _check_gamma(gamma: float) -> None:
    if not 0.0 <= gamma < 1.0:
        raise ValueError(f"gamma = {gamma!r}: expected a loss of effectiveness in [0, 1)")


def axis_coefficients(af: Airframe, axis: Axis, airspeed_m_s: float) -> AxisCoefficients:
    """The paper's dimensional derivatives of ``axis`` at ``airspeed_m_s``.

    Parameters
    ----------
    af : Airframe
        The airframe (wing geometry, derivative tables, inertia, air density).
    axis : {"roll", "pitch", "yaw"}
        The axis.
    airspeed_m_s : float
        Airspeed (m/s), >= 0.

    Returns
    -------
    AxisCoefficients
        Inertia, damping and stiffness of the axis.

    Raises
    ------
    ValueError
        For an unknown axis or a negative or NaN airspeed.

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> c = axis_coefficients(load_airframe(), "roll", 0.0)
    >>> c.inertia, c.damping == 0.0, c.stiffness == 0.0    # hover: a pure inertia (DS-1 Jx)
    (1.6, True, True)
    """
    if axis not in AXES:
        raise ValueError(f"axis {axis!r}: expected one of {', '.join(AXES)}")
    V = float(airspeed_m_s)
    if not V >= 0.0:
        raise ValueError(f"airspeed {airspeed_m_s!r}: expected a speed >= 0 m/s")
    w = af.wing
    d = af.derivatives.at(V)
    rho = af.air_density_kg_m3
    qbar = 0.5 * rho * V * V
    J = np.diag(af.inertia_kg_m2)
    if axis == "roll":
        return AxisCoefficients(axis, V, float(J[0]),
                                rho * V * w.area_m2 * w.span_m**2 * d["C_lp"] / 4, 0.0)
    if axis == "pitch":
        return AxisCoefficients(axis, V, float(J[1]),
                                rho * V * w.area_m2 * w.chord_m**2 * d["C_mq"] / 4,
                                qbar * w.area_m2 * w.chord_m * d["C_malpha"])
    return AxisCoefficients(axis, V, float(J[2]),
                            rho * V * w.area_m2 * w.span_m**2 * d["C_nr"] / 4,
                            -qbar * w.area_m2 * w.span_m * d["C_nbeta"])


def rate_model(af: Airframe, axis: Axis, airspeed_m_s: float, gamma: float = 0.0,
               ) -> ct.TransferFunction:
    """Moment (N m) -> body rate (rad/s) of ``axis`` (paper eq 1-3), as a python-control LTI.

    Roll is first order; pitch and yaw are written over the common denominator
    J s^2 - M_rate s - M_stiffness with a zero at the origin, as in the paper.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    airspeed_m_s : float
        Airspeed (m/s), >= 0.
    gamma : float
        Loss of control effectiveness of the axis' moment, in [0, 1].

    Returns
    -------
    control.TransferFunction
        G(s), SISO.

    Raises
    ------
    ValueError
        For an unknown axis, a negative airspeed or gamma outside [0, 1].

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> G = rate_model(load_airframe(), "pitch", 13.0, gamma=0.2)
    >>> G.num[0][0].tolist()[1]          # the zero at the origin of eq 2
    0.0
    """
    _check_gamma(gamma)
    c = axis_coefficients(af, axis, airspeed_m_s)
    k = 1.0 - gamma
    if axis == "roll":
        return ct.tf([k], [c.inertia, -c.damping])
    return ct.tf([k, 0.0], [c.inertia, -c.damping, -c.stiffness])


def attitude_model(af: Airframe, axis: Axis, airspeed_m_s: float, gamma: float = 0.0,
                   ) -> ct.StateSpace:
    """Moment -> [rate; angle] of ``axis`` as a minimal state-space model.

    For pitch and yaw this is the rate model of eq 2-3 with the zero at the origin cancelled
    by the integration to angle.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    airspeed_m_s : float
        Airspeed (m/s), >= 0.
    gamma : float
        Loss of control effectiveness of the axis' moment, in [0, 1].

    Returns
    -------
    control.StateSpace
        States [angle (rad), rate (rad/s)], input the moment (N m), outputs 0 = rate (rad/s)
        and 1 = angle (rad).

    Raises
    ------
    ValueError
        For an unknown axis, a negative airspeed or gamma outside [0, 1].

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> sys = attitude_model(load_airframe(), "roll", 0.0)
    >>> sys.nstates, sys.noutputs
    (2, 2)
    """
    _check_gamma(gamma)
    c = axis_coefficients(af, axis, airspeed_m_s)
    k = 1.0 - gamma
    A = np.array([[0.0, 1.0], [c.stiffness / c.inertia, c.damping / c.inertia]])
    B = np.array([[0.0], [k / c.inertia]])
    C = np.array([[0.0, 1.0], [1.0, 0.0]])
    return ct.ss(A, B, C, np.zeros((2, 1)))
