"""The weighted least-squares allocation problem shared by the QP allocators.

Every control step the QP allocators (``qp_osqp.QPAllocator``, ``active_set.ActiveSetAllocator``)
solve the same box-constrained weighted least-squares problem

    minimise    ||W_v (B u - v)||^2  +  eps * ||W_u (u - u_pref)||^2
    subject to  lo <= u <= hi

``W_v = diag(w_v)`` weights the virtual axes by priority (attitude moments above forces, so
that when the command is infeasible the moments are tracked first); the small second term
(``eps`` << 1) picks, among the allocations that achieve ``v``, the one closest to the
preferred actuator vector ``u_pref`` (e.g. surfaces at zero, pushers off, rotors at hover trim)
and makes the problem strictly convex. ``lo``/``hi`` are the position limits intersected with
the rate limits (``interface.step_bounds``).

Normalised form, the one the solvers see: ``min 1/2 u'Hn u + qn'u`` with
``Hn = c (B'W_v²B + eps W_u²)``, ``qn = -c (B'W_v² v + eps W_u² u_pref)`` and
``c = 1 / max diag(B'W_v²B + eps W_u²)`` (so max diag Hn = 1 whatever the units of ``v``).
``Hn`` is rebuilt only when ``B`` changes (bit-identical ``B`` keeps it).

This module holds that problem, the input validation, the per-step bounds, the invalid-input
hold and the fallback shared by the QP algorithms; each algorithm file adds only its solve.

Invalid input (status ``INVALID_INPUT``): a non-finite ``v``, ``B``, ``u_pref`` or ``u_prev``
cannot be allocated; the allocator holds the previous command (clipped into the current,
finite, bounds) or, before the first valid step, ``u_pref`` clipped. Non-finite per-step
limits are replaced by the limits given at construction. Nothing non-finite is ever returned
(for ``INVALID_INPUT`` the reported ``v_achieved`` and ``residual`` use ``B`` and ``v`` with
their non-finite entries replaced by 0).

Fallback (status ``FALLBACK``), when the solver fails: of the solver's iterate clipped into the
bounds (when finite) and the PX4-style pseudo-inverse + sequential desaturation + clipping
solution, the one with the lower QP cost, so it is never worse (in the QP's own metric) than
the baseline allocator.
"""

from __future__ import annotations

import time
from typing import TypedDict, Unpack

import numba
import numpy as np

from vtolftc.firmware_sim.autopilot.allocation.interface import (
    AllocationResult,
    AllocationStatus,
    AllocatorStats,
    as_vec,
    new_result,
    step_bounds,
    vec_arg,
)
from vtolftc.firmware_sim.autopilot.allocation.pseudo_inverse import PseudoInverseAllocator

__all__ = ["ProblemOptions", "WLSAllocator"]


class ProblemOptions(TypedDict, total=False):
    """The optional parts of the allocation problem, shared by every QP allocator's
    constructor (documented in :class:`WLSAllocator`): ``w_v``, ``w_u``, ``eps``, ``u_pref``,
    ``rate_limit``, ``dt`` and the fallback's ``thrust_axis``, ``roll_axis``, ``pitch_axis``,
    ``yaw_axis``."""

    w_v: np.ndarray | None
    w_u: np.ndarray | None
    eps: float
    u_pref: np.ndarray | None
    rate_limit: np.ndarray | None
    dt: float
    thrust_axis: int | None
    roll_axis: int | None
    pitch_axis: int | None
    yaw_axis: int | None

F64 = np.dtype(np.float64)
_perf_counter = time.perf_counter
# AllocationStatus members as module constants for the per-step path (an Enum class
# attribute costs ~75 ns in Python 3.11)
ST_SOLVED = AllocationStatus.SOLVED
ST_SOLVED_INACCURATE = AllocationStatus.SOLVED_INACCURATE
ST_FALLBACK = AllocationStatus.FALLBACK
ST_INVALID_INPUT = AllocationStatus.INVALID_INPUT


@numba.njit(cache=True)
def prepare_wls(v, B, pref, B_last, w_v2, reg, tri_r, tri_c, Hn, Px, BtW2s, scale, qn):
    """Validate the step's data and build the normalised QP (compiled).

    Returns -1 for non-finite input (nothing written), 0 when ``B`` equals ``B_last`` (only
    ``qn`` recomputed), 1 when ``B`` changed (``B_last``, ``Hn``, ``Px``, ``BtW2s``, ``scale``
    and ``qn`` recomputed). ``Hn = scale (B'W²B + diag(reg))`` with max diag(Hn) = 1,
    ``qn = -scale (B'W² v + reg * pref)``.
    """
    n_v, n_u = B.shape
    for k in range(n_v):
        if not np.isfinite(v[k]):
            return -1
    for j in range(n_u):
        if not np.isfinite(pref[j]):
            return -1
    changed = False
    for k in range(n_v):
        for j in range(n_u):
            b = B[k, j]
            if not np.isfinite(b):
                return -1
            if b != B_last[k, j]:
                changed = True
    if changed:
        dmax = 0.0
        for a in range(n_u):
            for b in range(a, n_u):
                acc = 0.0
                for k in range(n_v):
                    acc += B[k, a] * w_v2[k] * B[k, b]
                if a == b:
                    acc += reg[a]
                    dmax = max(dmax, acc)
                Hn[a, b] = acc
                Hn[b, a] = acc
        sc = 1.0 / dmax if dmax > 0.0 else 1.0
        scale[0] = sc
        for a in range(n_u):
            for b in range(n_u):
                Hn[a, b] *= sc
            for k in range(n_v):
                BtW2s[a, k] = B[k, a] * w_v2[k] * sc
        for t in range(tri_r.size):
            Px[t] = Hn[tri_r[t], tri_c[t]]
        for k in range(n_v):
            for j in range(n_u):
                B_last[k, j] = B[k, j]
    sc = scale[0]
    for j in range(n_u):
        acc = 0.0
        for k in range(n_v):
            acc += BtW2s[j, k] * v[k]
        qn[j] = -(acc + sc * reg[j] * pref[j])
    return 1 if changed else 0



class WLSAllocator:
    """Base of the QP allocators: the problem, validation, bounds, invalid-input hold, fallback.

    A subclass implements ``_solve(v, B, pref, lo, hi, B_changed, t0)``: solve the normalised
    QP held in ``self._Hn`` / ``self._qn`` within ``[lo, hi]`` and return ``self._finish(...)``.

    Parameters
    ----------
    n_v : int
        Number of virtual axes (e.g. 5, see ``AXES_5``).
    u_min, u_max : numpy.ndarray
        Actuator position limits (n_u,), normalised units, finite, ``u_min <= u_max``.
    **options
        The rest of the problem, all optional (:class:`ProblemOptions`; every QP allocator
        takes them and passes them here):
    w_v : numpy.ndarray, optional
        Virtual-axis weights (n_v,), > 0; squared in the cost. Axis priority: e.g.
        ``[1, 1, 10, 10, 3]`` (forces in N, moments in N m) tracks roll/pitch first.
    w_u : numpy.ndarray, optional
        Actuator weights (n_u,) for the secondary objective (default ones).
    eps : float
        Weight of the secondary objective (default 1e-6, absolute, in the units of the weighted
        virtual command squared per actuator unit squared).
    u_pref : numpy.ndarray, optional
        Preferred actuator vector (n_u,) (default clip(0, u_min, u_max)).
    rate_limit : numpy.ndarray, optional
        Actuator rate limits (n_u,) [normalised units / s], ``inf`` = none; None: no rate limit.
    dt : float
        Control period [s] for the rate limits (default 1/250).
    thrust_axis, roll_axis, pitch_axis, yaw_axis : int or None
        Axis indices for the fallback's sequential desaturation (defaults follow ``AXES_5``).
    """

    def __init__(self, n_v: int, u_min: np.ndarray, u_max: np.ndarray,
                 **options: Unpack[ProblemOptions]) -> None:
        unknown = set(options) - set(ProblemOptions.__annotations__)
        if unknown:
            raise TypeError(f"unexpected allocator option(s): {', '.join(sorted(unknown))}")
        w_v = options.get("w_v")
        w_u = options.get("w_u")
        eps = options.get("eps", 1e-6)
        u_pref = options.get("u_pref")
        rate_limit = options.get("rate_limit")
        dt = options.get("dt", 1.0 / 250.0)
        thrust_axis = options.get("thrust_axis", 0)
        roll_axis = options.get("roll_axis", 2)
        pitch_axis = options.get("pitch_axis", 3)
        yaw_axis = options.get("yaw_axis", 4)
        self.u_min = np.asarray(u_min, dtype=float).copy()
        self.u_max = np.asarray(u_max, dtype=float).copy()
        n_u = self.u_min.size
        if self.u_min.ndim != 1 or self.u_max.shape != (n_u,):
            raise ValueError(
                f"u_min/u_max: expected equal 1-D shapes, got {self.u_min.shape} "
                f"and {self.u_max.shape}"
            )
        if not (np.all(np.isfinite(self.u_min)) and np.all(np.isfinite(self.u_max))):
            raise ValueError("u_min/u_max must be finite")
        if np.any(self.u_min > self.u_max):
            raise ValueError("u_min must be <= u_max element-wise")
        if n_v < 1:
            raise ValueError(f"n_v must be >= 1, got {n_v}")
        self.n_v = int(n_v)
        self.n_u = int(n_u)
        self.w_v = np.ones(n_v) if w_v is None else as_vec(w_v, n_v, "w_v").copy()
        self.w_u = np.ones(n_u) if w_u is None else as_vec(w_u, n_u, "w_u").copy()
        if np.any(self.w_v <= 0) or not np.all(np.isfinite(self.w_v)):
            raise ValueError(f"w_v must be finite and > 0, got {self.w_v}")
        if np.any(self.w_u <= 0) or not np.all(np.isfinite(self.w_u)):
            raise ValueError(f"w_u must be finite and > 0, got {self.w_u}")
        if not (eps > 0 and np.isfinite(eps)):
            raise ValueError(f"eps must be finite and > 0, got {eps}")
        self.eps = float(eps)
        self.u_pref = (
            np.clip(0.0, self.u_min, self.u_max)
            if u_pref is None
            else as_vec(u_pref, n_u, "u_pref").copy()
        )
        if not np.all(np.isfinite(self.u_pref)):
            raise ValueError("u_pref must be finite")
        if rate_limit is not None:
            rate_limit = as_vec(rate_limit, n_u, "rate_limit").copy()
            if np.any(rate_limit <= 0) or np.any(np.isnan(rate_limit)):
                raise ValueError("rate_limit must be > 0 (inf = unlimited)")
        self.rate_limit = rate_limit
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.dt = float(dt)

        self._baseline = PseudoInverseAllocator(
            self.u_min,
            self.u_max,
            u_trim=self.u_pref,
            thrust_axis=thrust_axis,
            roll_axis=roll_axis,
            pitch_axis=pitch_axis,
            yaw_axis=yaw_axis,
        )

        # Upper triangle of the dense n_u x n_u Hn, in CSC (column-major) order.
        self._tri_c = np.concatenate([np.full(j + 1, j) for j in range(n_u)]).astype(np.int64)
        self._tri_r = np.concatenate([np.arange(j + 1) for j in range(n_u)]).astype(np.int64)
        self._P_indptr = np.concatenate([[0], np.cumsum(np.arange(1, n_u + 1))]).astype(np.int64)
        self._w_v2 = self.w_v**2
        self._reg = self.eps * self.w_u**2
        self._zeros_u = np.zeros(n_u)

        # Data derived from the current B (recomputed, in place, only when B changes).
        self._B_last = np.full((n_v, n_u), np.nan)
        self._Hn = np.zeros((n_u, n_u))  # normalised Hessian, max diag = 1
        self._Px = np.zeros(self._tri_r.size)  # its upper triangle, CSC order
        self._scale = np.ones(1)  # Hn = scale * (B'W²B + eps W_u²)
        self._BtW2s = np.zeros((n_u, n_v))  # scale * B' W_v²
        self._qn = np.zeros(n_u)  # normalised linear term of the current step

        self._u_last: np.ndarray | None = None
        self.stats = AllocatorStats()

    # ------------------------------------------------------------------------------------
    def reset(self, u0: np.ndarray | None = None) -> None:
        """Forget the previous command and the solver state (warm start); optionally set the
        previous command to ``u0`` (n_u,)."""
        self._u_last = None if u0 is None else as_vec(u0, self.n_u, "u0").copy()
        self._B_last.fill(np.nan)

    @property
    def u_last(self) -> np.ndarray | None:
        """Previous allocated command (n_u,), or None before the first step."""
        return None if self._u_last is None else self._u_last.copy()

    def cost(
        self, u: np.ndarray, v: np.ndarray, B: np.ndarray, u_pref: np.ndarray | None = None
    ) -> float:
        """QP objective ``||W_v (B u - v)||² + eps ||W_u (u - u_pref)||²`` (unnormalised)."""
        r = self.w_v * (B @ u - v)
        d = self.w_u * (u - (self.u_pref if u_pref is None else u_pref))
        return float(r @ r + self.eps * (d @ d))

    def tracking_cost(self, u: np.ndarray, v: np.ndarray, B: np.ndarray) -> float:
        """Weighted tracking error ``||W_v (B u - v)||²`` (the primary objective)."""
        r = self.w_v * (B @ u - v)
        return float(r @ r)

    # ------------------------------------------------------------------------------------
    def allocate(
        self,
        v: np.ndarray,
        B: np.ndarray,
        *,
        u_min: np.ndarray | None = None,
        u_max: np.ndarray | None = None,
        u_pref: np.ndarray | None = None,
        u_prev: np.ndarray | None = None,
    ) -> AllocationResult:
        """Allocate one step.

        Parameters
        ----------
        v : numpy.ndarray
            Virtual command (n_v,) [N, N m], NED/FRD.
        B : numpy.ndarray
            Effectiveness (n_v x n_u) [N or N m per normalised unit]; may change every step.
        u_min, u_max : numpy.ndarray, optional
            Per-step position limits (n_u,), default the construction limits (e.g. narrowed
            by a flight mode); non-finite entries fall back to those.
        u_pref : numpy.ndarray, optional
            Per-step preferred actuator vector (n_u,), default the construction one.
        u_prev : numpy.ndarray, optional
            Actuator state for the rate limits (n_u,), default the previous result.

        Returns
        -------
        AllocationResult
            ``u`` is finite and within the (rate-limited) bounds.
        """
        t0 = _perf_counter()
        n_u = self.n_u
        # float64 ndarrays of the right shape (the autopilot's case) pass without copies
        if type(v) is not np.ndarray or v.dtype != F64:
            v = np.asarray(v, dtype=float)
        if type(B) is not np.ndarray or B.dtype != F64:
            B = np.asarray(B, dtype=float)
        if v.shape != (self.n_v,):
            raise ValueError(f"v: expected shape ({self.n_v},), got {v.shape}")
        if B.shape != (self.n_v, n_u):
            raise ValueError(f"B: expected shape ({self.n_v}, {n_u}), got {B.shape}")

        umin_in = self.u_min if u_min is None else vec_arg(u_min, n_u, "u_min")
        umax_in = self.u_max if u_max is None else vec_arg(u_max, n_u, "u_max")
        prev = self._u_last if u_prev is None else vec_arg(u_prev, n_u, "u_prev")
        lo = np.empty(n_u)
        hi = np.empty(n_u)
        rate = self.rate_limit
        prev_ok = step_bounds(
            self.u_min,
            self.u_max,
            umin_in,
            umax_in,
            self._zeros_u if prev is None else prev,
            prev is not None,
            self._zeros_u if rate is None else rate,
            rate is not None,
            self.dt,
            lo,
            hi,
        )
        pref = self.u_pref if u_pref is None else vec_arg(u_pref, n_u, "u_pref")
        code = -1
        if prev_ok:
            code = prepare_wls(
                v,
                B,
                pref,
                self._B_last,
                self._w_v2,
                self._reg,
                self._tri_r,
                self._tri_c,
                self._Hn,
                self._Px,
                self._BtW2s,
                self._scale,
                self._qn,
            )
        if code < 0:
            hold = self._u_last if self._u_last is not None else self.u_pref
            return self._finish(
                np.clip(hold, lo, hi),
                v,
                B,
                ST_INVALID_INPUT,
                0,
                0.0,
                t0,
                "non-finite input",
                False,
            )
        return self._solve(v, B, pref, lo, hi, code == 1, t0)

    def _solve(self, v: np.ndarray, B: np.ndarray, pref: np.ndarray, lo: np.ndarray,
               hi: np.ndarray, B_changed: bool, t0: float) -> AllocationResult:
        raise NotImplementedError

    def _fallback(self, v: np.ndarray, B: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  pref: np.ndarray, x: np.ndarray | None) -> np.ndarray:
        """The better (lower QP cost) of the baseline allocator's answer and ``x`` clipped
        into ``[lo, hi]`` (``x`` None or non-finite: the baseline's)."""
        u = self._baseline.compute(v, B, lo, hi, pref)
        if x is not None:
            u_it = np.clip(x, lo, hi)
            if self.cost(u_it, v, B, pref) < self.cost(u, v, B, pref):
                u = u_it
        return u

    def _finish(
        self,
        u: np.ndarray,
        v: np.ndarray,
        B: np.ndarray,
        status: AllocationStatus,
        iters: int,
        t_solve: float,
        t0: float,
        st_str: str,
        polished: bool,
    ) -> AllocationResult:
        if status == ST_INVALID_INPUT:  # report finite numbers only
            B = np.nan_to_num(B, nan=0.0, posinf=0.0, neginf=0.0)
            v = np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0)
        va = B @ u
        self._u_last = u
        res = new_result(u, va, va - v, status, iters, t_solve, _perf_counter() - t0, st_str,
                          polished)
        self.stats.record(res)
        return res
