"""PX4-style baseline allocator: pseudo-inverse + sequential desaturation + clipping.

The PX4 control-allocator idea (``ControlAllocationPseudoInverse`` +
``ControlAllocationSequentialDesaturation``, MC_AIRMODE = 0): ``u = u_trim + B⁺ (v - B u_trim)``
without the yaw part, desaturate along the thrust column of ``B⁺`` (only reducing thrust), then
along the roll and pitch columns, add yaw and desaturate along the yaw column, reduce thrust
again if needed, and finally clip to the limits. Generalised to a generic ``n_u`` and SI
effectiveness: PX4's "ignore actuators with |d_i| < 0.2 in the normalised mix" becomes
``|d_i| < 0.2 max_j |d_j|``.

It is the baseline the QP allocators are compared with, and their fallback when the QP solver
fails. Units and frames as in ``interface``.
"""

from __future__ import annotations

import time

import numpy as np

from vtolftc.firmware_sim.autopilot.allocation.interface import (
    AllocationResult,
    AllocationStatus,
    AllocatorStats,
    as_vec,
)

__all__ = ["PseudoInverseAllocator"]


class PseudoInverseAllocator:
    """PX4-style baseline: pseudo-inverse + sequential desaturation + clipping.

    ``u = u_trim + B⁺ (v - B u_trim)`` (the minimum-norm deviation from the trim actuator
    vector), then PX4's ``mixAirmodeDisabled`` / ``mixYaw`` sequence (see module docstring),
    then clipping into the limits. ``B⁺`` is recomputed only when ``B`` changes.

    Parameters
    ----------
    u_min, u_max : numpy.ndarray
        Actuator position limits (n_u,), normalised units.
    u_trim : numpy.ndarray, optional
        Trim / preferred actuator vector (n_u,); default clip(0, u_min, u_max).
    thrust_axis, roll_axis, pitch_axis, yaw_axis : int or None
        Indices of the vertical-force (NED z, negative up) and moment axes in ``v`` (defaults
        follow ``AXES_5``). ``None`` skips that desaturation step.
    weights_u : numpy.ndarray, optional
        Actuator weights (n_u,) for a weighted pseudo-inverse ``B⁺ = W⁻¹B'(B W⁻¹ B')⁻¹``
        (default: PX4's plain pseudo-inverse).
    """

    def __init__(
        self,
        u_min: np.ndarray,
        u_max: np.ndarray,
        *,
        u_trim: np.ndarray | None = None,
        thrust_axis: int | None = 0,
        roll_axis: int | None = 2,
        pitch_axis: int | None = 3,
        yaw_axis: int | None = 4,
        weights_u: np.ndarray | None = None,
    ) -> None:
        self.u_min = np.asarray(u_min, dtype=float).copy()
        self.u_max = np.asarray(u_max, dtype=float).copy()
        self.n_u = self.u_min.size
        if self.u_max.shape != (self.n_u,) or np.any(self.u_min > self.u_max):
            raise ValueError("u_min/u_max: need equal shapes and u_min <= u_max")
        self.u_trim = (
            np.clip(0.0, self.u_min, self.u_max)
            if u_trim is None
            else as_vec(u_trim, self.n_u, "u_trim")
        )
        self.thrust_axis = thrust_axis
        self.roll_axis = roll_axis
        self.pitch_axis = pitch_axis
        self.yaw_axis = yaw_axis
        self.weights_u = None if weights_u is None else as_vec(weights_u, self.n_u, "weights_u")
        self._B_cached: np.ndarray | None = None
        self._pinv: np.ndarray | None = None
        self.stats = AllocatorStats()

    def reset(self, u0: np.ndarray | None = None) -> None:
        """Forget the cached pseudo-inverse (the allocator keeps no other state; ``u0`` is
        accepted for the ``Allocator`` protocol and ignored)."""
        self._B_cached = None
        self._pinv = None

    def pinv(self, B: np.ndarray) -> np.ndarray:
        """(Weighted) pseudo-inverse (n_u x n_v) of ``B``, cached while ``B`` does not
        change."""
        if self._pinv is None or self._B_cached is None or not np.array_equal(B, self._B_cached):
            if self.weights_u is None:
                self._pinv = np.linalg.pinv(B)
            else:
                s = 1.0 / np.sqrt(self.weights_u)  # B⁺_W = S (B S)⁺ with S = W^-1/2
                self._pinv = s[:, None] * np.linalg.pinv(B * s[None, :])
            self._B_cached = np.array(B, dtype=float, copy=True)
        return self._pinv

    # -- PX4 ControlAllocationSequentialDesaturation, generalised ------------------------------
    @staticmethod
    def _desaturation_gain(d: np.ndarray, u: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
        dmax = float(np.max(np.abs(d))) if d.size else 0.0
        if dmax <= 0.0:
            return 0.0
        use = np.abs(d) >= 0.2 * dmax
        k_min = 0.0
        k_max = 0.0
        below = use & (u < lo)
        above = use & (u > hi)
        if np.any(below):
            k = (lo[below] - u[below]) / d[below]
            k_min = min(k_min, float(k.min()))
            k_max = max(k_max, float(k.max()))
        if np.any(above):
            k = (hi[above] - u[above]) / d[above]
            k_min = min(k_min, float(k.min()))
            k_max = max(k_max, float(k.max()))
        return k_min + k_max

    def _desaturate(
        self,
        u: np.ndarray,
        d: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        increase_only: bool = False,
    ) -> np.ndarray:
        gain = self._desaturation_gain(d, u, lo, hi)
        if increase_only and gain < 0.0:
            return u
        u = u + gain * d
        gain = 0.5 * self._desaturation_gain(d, u, lo, hi)
        return u + gain * d

    def compute(
        self,
        v: np.ndarray,
        B: np.ndarray,
        lo: np.ndarray | None = None,
        hi: np.ndarray | None = None,
        u_trim: np.ndarray | None = None,
    ) -> np.ndarray:
        """Actuator command (n_u,) clipped into ``[lo, hi]`` (defaults: position limits).

        Parameters
        ----------
        v : numpy.ndarray
            Virtual command (n_v,) [N, N m], finite.
        B : numpy.ndarray
            Effectiveness (n_v x n_u), finite.
        lo, hi : numpy.ndarray, optional
            Bounds (n_u,), default the position limits.
        u_trim : numpy.ndarray, optional
            Trim vector (n_u,), default the construction one.

        Returns
        -------
        numpy.ndarray
            ``u`` (n_u,) within ``[lo, hi]``.
        """
        lo = self.u_min if lo is None else lo
        hi = self.u_max if hi is None else hi
        u_trim = self.u_trim if u_trim is None else u_trim
        M = self.pinv(B)
        dv = v - B @ u_trim
        yaw = self.yaw_axis
        if yaw is not None:
            dv_noyaw = dv.copy()
            dv_noyaw[yaw] = 0.0
        else:
            dv_noyaw = dv
        u = u_trim + M @ dv_noyaw
        if self.thrust_axis is not None:
            # NED: a positive gain along the Fz column increases Fz, i.e. reduces upward thrust
            u = self._desaturate(u, M[:, self.thrust_axis], lo, hi, increase_only=True)
        for ax in (self.roll_axis, self.pitch_axis):
            if ax is not None:
                u = self._desaturate(u, M[:, ax], lo, hi)
        if yaw is not None:
            u = u + M[:, yaw] * dv[yaw]
            u = self._desaturate(u, M[:, yaw], lo, hi)
            if self.thrust_axis is not None:
                u = self._desaturate(u, M[:, self.thrust_axis], lo, hi, increase_only=True)
        return np.clip(u, lo, hi)

    def allocate(
        self,
        v: np.ndarray,
        B: np.ndarray,
        *,
        u_min: np.ndarray | None = None,
        u_max: np.ndarray | None = None,
        u_pref: np.ndarray | None = None,
    ) -> AllocationResult:
        """Allocate ``v`` (n_v,) [N, N m] with effectiveness ``B`` (n_v x n_u).

        Parameters
        ----------
        v, B : numpy.ndarray
            Virtual command and effectiveness.
        u_min, u_max : numpy.ndarray, optional
            Per-step limits (n_u,), default the construction ones.
        u_pref : numpy.ndarray, optional
            Trim vector (n_u,) for this step, default the construction ``u_trim``.

        Returns
        -------
        AllocationResult
            Status ``PSEUDO_INVERSE``; non-finite input holds ``u_trim`` clipped (status
            ``INVALID_INPUT``).
        """
        t0 = time.perf_counter()
        v = np.asarray(v, dtype=float)
        B = np.asarray(B, dtype=float)
        lo = self.u_min if u_min is None else np.asarray(u_min, dtype=float)
        hi = self.u_max if u_max is None else np.asarray(u_max, dtype=float)
        ut = self.u_trim if u_pref is None else np.asarray(u_pref, dtype=float)
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(B)) and np.all(np.isfinite(ut))):
            u = np.clip(np.nan_to_num(self.u_trim), self.u_min, self.u_max)
            status, reason = AllocationStatus.INVALID_INPUT, "non-finite input"
        else:
            u = self.compute(v, B, lo, hi, ut)
            status, reason = AllocationStatus.PSEUDO_INVERSE, "pseudo-inverse"
        if status == AllocationStatus.INVALID_INPUT:  # report finite numbers only
            B = np.nan_to_num(B, nan=0.0, posinf=0.0, neginf=0.0)
            v = np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0)
        va = B @ u
        res = AllocationResult(
            u=u,
            v_achieved=va,
            residual=va - v,
            status=status,
            iterations=0,
            solve_time_s=0.0,
            wall_time_s=time.perf_counter() - t0,
            solver_status=reason,
        )
        self.stats.record(res)
        return res


