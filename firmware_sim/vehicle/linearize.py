"""Numerical linearisation of the nonlinear vehicle about a trim point.

The 12 error states are ``[pn, pe, pd, vn, ve, vd, dphi, dtheta, dpsi, p, q, r]``: NED
position and velocity deviations, the attitude deviation as a small rotation vector in body
axes (``q = q0 * [1, d/2]``; at a level trim its components are roll, pitch and yaw angle
deviations) and the body rates. The inputs are the actuator *positions* (normalised as the
commands), i.e. the actuator lags are left out: add them in series when needed. Derivatives by
central differences of the compiled equations of motion. Valid about steady trims (zero body
rates), which is what :mod:`vtolftc.firmware_sim.vehicle.trim` produces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vtolftc.base.rotation import quat_mul
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.model import Vehicle

STATE_NAMES = ("pn", "pe", "pd", "vn", "ve", "vd", "dphi", "dtheta", "dpsi", "p", "q", "r")


@dataclass(frozen=True)
class LinearModel:
    """dx/dt = A x + B u about (x0, u0); states per :data:`STATE_NAMES`, inputs by name."""

    A: np.ndarray
    B: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    x0: np.ndarray
    u0: np.ndarray

    def a(self, row: str, col: str) -> float:
        """One entry of A by state names, e.g. ``a("q", "dtheta")``."""
        return float(self.A[self.state_names.index(row), self.state_names.index(col)])

    def b(self, row: str, col: str) -> float:
        """One entry of B by state and input names, e.g. ``b("q", "elevator")``."""
        return float(self.B[self.state_names.index(row), self.input_names.index(col)])


def linearize(vehicle: Vehicle, x0: np.ndarray, u0: np.ndarray | None = None,
              eps: float = 1e-6) -> LinearModel:
    """Jacobians of the rigid-body dynamics about ``x0`` with actuator positions ``u0``
    (default: the actuator positions stored in ``x0``). Uses the vehicle's current faults."""
    n = dyn.N_RIGID
    x0 = np.asarray(x0, dtype=float)
    u0 = x0[n:].copy() if u0 is None else np.asarray(u0, dtype=float)
    q0 = x0[6:10] / np.linalg.norm(x0[6:10])
    q0c = q0 * np.array([1.0, -1.0, -1.0, -1.0])
    n_u = u0.size

    def f(xe: np.ndarray, du: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[0:6] += xe[0:6]
        dq = np.concatenate([[1.0], 0.5 * xe[6:9]])
        q = quat_mul(q0, dq)
        x[6:10] = q / np.linalg.norm(q)
        x[10:13] += xe[9:12]
        x[n:] = u0 + du
        dx, _ = vehicle.derivatives(x, x[n:])
        # Attitude-error rate in body axes: 2 vec(q0^* q').
        datt = 2.0 * quat_mul(q0c, dx[6:10])[1:]
        return np.concatenate([dx[0:6], datt, dx[10:13]])

    A = np.empty((12, 12))
    B = np.empty((12, n_u))
    z = np.zeros(12)
    zu = np.zeros(n_u)
    for j in range(12):
        e = np.zeros(12)
        e[j] = eps
        A[:, j] = (f(e, zu) - f(-e, zu)) / (2 * eps)
    for j in range(n_u):
        e = np.zeros(n_u)
        e[j] = eps
        B[:, j] = (f(z, e) - f(z, -e)) / (2 * eps)
    return LinearModel(A, B, STATE_NAMES, tuple(vehicle.airframe.actuator_names), x0.copy(),
                       u0.copy())
