"""Nominal control-effectiveness matrix B(V) of the airframe, for control allocation.

``B(V)`` maps the 15 normalised actuator commands (airframe order: 8 lift rotors, 2 pushers,
aileron_left, aileron_right, elevator, rudder_left, rudder_right) to the five virtual axes
``[Fz, Fx, L, M, N]``:

- ``Fz``: force along the body z axis (FRD, positive down; N). In level flight it is the NED
  down force, so lifting is negative;
- ``Fx``: force along the body x axis (forward; N);
- ``L, M, N``: roll, pitch and yaw moments about the FRD body axes at the CG (N m).

Per unit command (the Jacobian of the vehicle's force/moment model in the actuator positions,
evaluated in wings-level flight with the velocity along the body x axis, alpha = beta = 0):

- a rotor with thrust axis ``a`` at position ``r`` gives the force ``T_max f a`` and the moment
  ``r x (T_max f a) + T_max f tau``, where ``tau = -torque_to_thrust * spin_axis`` is its
  reaction torque per newton and ``f = clip(1 - V_axial / V0, 0, 1.25)`` the thrust fade with
  axial inflow (``V_axial = V a_x``: the lift rotors see none in level flight, the pushers
  the full airspeed);
- a surface, per unit normalised command (``max_deflection_rad`` rad), gives moments scaling
  with the dynamic pressure ``q = rho V^2 / 2``: each aileron half of ``q S b Cl_da`` (and
  ``Cn_da``) with opposite signs (``d_a = (d_left - d_right) / 2``), the elevator
  ``q S c Cm_de`` and the lift change ``-q S CL_de`` along z, each rudder half of
  ``q S b Cn_dr`` (and ``Cl_dr``). Side forces are not part of the five axes.

This is the NOMINAL model from the airframe file: it knows nothing of injected faults
(passive FTC) and is evaluated at the measured airspeed. It must stay consistent with
``vtolftc.firmware_sim.vehicle.dynamics`` (tested there by finite differences), without importing
it.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe

__all__ = ["EffectivenessModel"]


class EffectivenessModel:
    """Nominal ``B(V)`` (5 x n_actuators) of an airframe; see the module docstring.

    The airspeed-independent rotor part and the per-``q`` surface part are precomputed, so
    :meth:`matrix` costs a few microseconds.
    """

    def __init__(self, airframe: Airframe) -> None:
        self.airframe = airframe
        rotors = airframe.rotors
        self.n_u = airframe.n_actuators
        self.n_rotors = len(rotors)
        n_u = self.n_u
        # Rotor columns at zero inflow, and each rotor's axial-fade slope per m/s of airspeed.
        self._B_rot = np.zeros((5, n_u))
        self._fade_slope = np.zeros(n_u)   # d(fade)/dV for V along body x
        for i, r in enumerate(rotors):
            a = np.asarray(r.thrust_axis, dtype=float)
            pos = np.asarray(r.position_m, dtype=float)
            F = r.max_thrust_N * a
            tau = -r.torque_to_thrust_m * np.asarray(r.spin_axis, dtype=float) * r.max_thrust_N
            M = np.cross(pos, F) + tau
            self._B_rot[:, i] = [F[2], F[0], M[0], M[1], M[2]]
            self._fade_slope[i] = a[0] / r.zero_thrust_axial_speed_m_s
        # Surface columns per unit dynamic pressure (N or N m per Pa per unit command).
        w = airframe.wing
        S, b, c = w.area_m2, w.span_m, w.chord_m
        d = airframe.surfaces.max_deflection_rad
        self._B_q = np.zeros((5, n_u))
        names = airframe.actuator_names

        def col(name: str) -> int:
            return names.index(name)

        ail = [(n, s) for n, s in (("aileron_left", 0.5), ("aileron_right", -0.5)) if n in names]
        for side, sgn in ail or [("aileron", 1.0)]:
            j = col(side)
            self._B_q[2, j] = S * b * w.Cl_da * sgn * d
            self._B_q[4, j] = S * b * w.Cn_da * sgn * d
        j = col("elevator")
        self._B_q[0, j] = -S * w.CL_de * d
        self._B_q[3, j] = S * c * w.Cm_de * d
        rud = [n for n in ("rudder_left", "rudder_right") if n in names]
        share = 0.5 if rud else 1.0
        for side in rud or ["rudder"]:
            j = col(side)
            self._B_q[2, j] = S * b * w.Cl_dr * share * d
            self._B_q[4, j] = S * b * w.Cn_dr * share * d
        self._rho = airframe.air_density_kg_m3
        self._faded = [j for j in range(n_u) if self._fade_slope[j] != 0.0]
        self._cache: dict[int, NDArray[np.float64]] = {}

    def matrix(self, airspeed_m_s: float, out: NDArray[np.float64] | None = None,
               ) -> NDArray[np.float64]:
        """``B(V)`` at the airspeed ``V`` [m/s] (non-finite or negative V counts as 0).

        Returns a new (5, n_u) array, or writes into ``out`` when given.
        """
        V = float(airspeed_m_s)
        if not math.isfinite(V) or V < 0.0:
            V = 0.0
        qbar = 0.5 * self._rho * V * V
        B = out if out is not None else np.empty((5, self.n_u))
        np.multiply(self._B_q, qbar, out=B)
        B += self._B_rot
        for j in self._faded:  # rotors with axial inflow (the pushers): thrust fades
            fade = min(1.25, max(0.0, 1.0 - self._fade_slope[j] * V))
            B[:, j] -= (1.0 - fade) * self._B_rot[:, j]
        return B

    def matrix_on_grid(self, airspeed_m_s: float, step_m_s: float = 0.1) -> NDArray[np.float64]:
        """``B`` at the airspeed rounded to a multiple of ``step_m_s`` (cached, read-only).

        The autopilot uses it so that ``B`` (hence the allocator's Hessian) changes only when the
        airspeed crosses a grid point; with 0.1 m/s the dynamic pressure differs from the
        exact one by less than 1 % above 10 m/s.
        """
        V = float(airspeed_m_s)
        k = round(V / step_m_s) if math.isfinite(V) and V > 0.0 else 0
        B = self._cache.get(k)
        if B is None:
            B = self.matrix(k * step_m_s)
            B.setflags(write=False)
            if len(self._cache) < 10_000:
                self._cache[k] = B
        return B

    def dynamic_pressure(self, airspeed_m_s: float) -> float:
        """``rho V^2 / 2`` [Pa] with the airframe's air density."""
        V = max(0.0, float(airspeed_m_s)) if math.isfinite(airspeed_m_s) else 0.0
        return 0.5 * self._rho * V * V
