"""Control allocation: map a virtual command ``v`` onto the actuators ``u`` with ``B u ≈ v``.

Two allocators share one interface (``allocate(v, B, ...) -> AllocationResult``):

``QPAllocator`` (the one the autopilot flies)
    Solves, every control step, the box-constrained weighted least-squares problem

        minimise    ||W_v (B u - v)||^2  +  eps * ||W_u (u - u_pref)||^2
        subject to  lo <= u <= hi

    with OSQP. ``W_v = diag(w_v)`` weights the virtual axes by priority (attitude moments above
    forces, so that when the command is infeasible the moments are tracked first); the small
    second term (``eps`` << 1) picks, among the allocations that achieve ``v``, the one closest
    to the preferred actuator vector ``u_pref`` (e.g. surfaces at zero, pushers off, rotors at
    hover trim) and makes the problem strictly convex.

    The bounds ``lo``/``hi`` are the actuator position limits, intersected, when rate limits are
    configured, with ``u_prev ± rate * dt`` (``u_prev`` is the previous allocated command unless
    the caller passes the measured/estimated actuator state). Position limits always win: where
    the intersection would be empty (the previous command lies more than one rate step outside
    the position limits, e.g. after a limit change) the interval collapses to the position-
    feasible value nearest to the rate-feasible interval, so the QP is always feasible.

    OSQP form: ``min 1/2 u'P u + q'u  s.t.  l <= A u <= h`` with ``P = c (B'W_v²B + eps W_u²)``
    (dense upper triangle, fixed sparsity pattern), ``q = -c (B'W_v² v + eps W_u² u_pref)``,
    ``A = I``; ``c = 1 / max diag(B'W_v²B + eps W_u²)`` normalises the problem so that OSQP's
    absolute tolerances mean the same thing whatever the units of ``v``. ``B`` may change every
    step (airspeed-dependent surface effectiveness): only the numerical values of ``P`` are
    updated in place (same sparsity pattern, no new setup, and no update at all when ``B`` is
    bit-identical to the previous step); ``q`` and the bounds are updated every step. OSQP is
    warm-started from the previous step's solution (primal and dual).

    Polish: ADMM converges slowly on this problem (the rotor null space has curvature ~eps, the
    moment rows ~1), but it identifies the active bounds early. OSQP's own ``polishing`` is
    off (OSQP 1.x prints a line to stdout on every polished solve without active bounds,
    osqp/osqp#785); instead ``box_qp_polish`` (a compiled primal active-set method started
    from OSQP's iterate) finishes the job and certifies the exact optimum through the KKT
    conditions. ``AllocationResult.polished`` says when it did; the status is then
    ``SOLVED`` even if ADMM itself stopped at its iteration limit (``solver_status`` keeps
    OSQP's own word). With ``polish=False`` the allocator relies on OSQP alone.

    Solver settings (tuned for a 250 Hz loop, overridable through ``settings=``):
    ``eps_abs = eps_rel = 1e-5`` (on the normalised problem), ``max_iter = 80``,
    ``time_limit = 1 ms``, ``check_termination = 5``, ``polishing = False`` (see above),
    ``adaptive_rho`` on, warm starting on. See ``benchmarks/bench_allocation.py`` for the
    measured cost.

    The returned ``u`` is always clipped into ``[lo, hi]`` (OSQP meets the bounds only to its
    tolerance), so limits are never violated.

    Fallback (status ``FALLBACK``) when neither the polish certifies an optimum nor OSQP
    reports ``solved``/``solved inaccurate`` (iteration or time limit, numerical trouble,
    non-finite iterate, exception): the allocator evaluates two candidates, the OSQP iterate
    clipped into the bounds (when finite) and the PX4-style pseudo-inverse + sequential
    desaturation + clipping solution (``PseudoInverseAllocator`` logic), and returns the one
    with the lower QP cost. The fallback is therefore never worse (in the QP's own metric)
    than the baseline allocator. OSQP is then warm-started from the returned ``u``.

    Invalid input (status ``INVALID_INPUT``): a non-finite ``v``, ``B``, ``u_pref`` or
    ``u_prev`` cannot be allocated; the allocator holds the previous command (clipped into the
    current, finite, bounds) or, before the first valid step, ``u_pref`` clipped. Non-finite
    per-step limits are replaced by the limits given at construction. Nothing non-finite is
    ever returned (for ``INVALID_INPUT`` the reported ``v_achieved`` and ``residual`` use ``B``
    and ``v`` with their non-finite entries replaced by 0).

    Every status is counted in ``QPAllocator.stats``.

``PseudoInverseAllocator`` (baseline for comparison)
    The PX4 control-allocator idea (``ControlAllocationPseudoInverse`` +
    ``ControlAllocationSequentialDesaturation``, MC_AIRMODE = 0): ``u = u_trim + B⁺ (v -
    B u_trim)`` without the yaw part, desaturate along the thrust column of ``B⁺`` (only
    reducing thrust), then along the roll and pitch columns, add yaw and desaturate along the
    yaw column, reduce thrust again if needed, and finally clip to the limits. Generalised to a
    generic ``n_u`` and SI effectiveness: PX4's "ignore actuators with |d_i| < 0.2 in the
    normalised mix" becomes ``|d_i| < 0.2 max_j |d_j|``.

Conventions: virtual command ``v`` in SI (forces in N, NED/FRD, so a negative vertical force
is upwards; moments in N m about the FRD body axes); ``u`` normalised (rotors 0..1, surfaces
-1..1, whatever the caller's ``B`` assumes). The default axis layout used by the baseline's
desaturation order is ``AXES_5 = ("fz", "fx", "roll", "pitch", "yaw")``; any other layout is
configured by indices.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
import osqp
import scipy.sparse as sp

__all__ = [
    "AXES_5",
    "AllocationResult",
    "AllocationStatus",
    "AllocatorStats",
    "PseudoInverseAllocator",
    "QPAllocator",
    "box_qp_polish",
    "rate_limited_bounds",
]

#: Default virtual-axis layout: vertical force (N, NED z), forward force (N), roll, pitch and
#: yaw moments (N m, FRD).
AXES_5: tuple[str, ...] = ("fz", "fx", "roll", "pitch", "yaw")

_DEFAULT_OSQP_SETTINGS: dict[str, Any] = {
    "verbose": False,
    "eps_abs": 1e-5,
    "eps_rel": 1e-5,
    "eps_prim_inf": 1e-6,
    "eps_dual_inf": 1e-6,
    "max_iter": 80,
    "time_limit": 1e-3,  # s; a 250 Hz step is 4 ms
    "check_termination": 5,
    "polishing": False,  # see box_qp_polish
    "adaptive_rho": True,
    "warm_starting": True,
    "scaling": 10,
}


class AllocationStatus(enum.IntEnum):
    """Outcome of one allocation step."""

    SOLVED = 0
    """OSQP converged to its tolerances; ``u`` is its solution clipped into the bounds."""
    SOLVED_INACCURATE = 1
    """OSQP reported 'solved inaccurate' (looser tolerance); its clipped solution is used."""
    FALLBACK = 2
    """OSQP failed (iteration/time limit, numerical error): best of clipped iterate and the
    pseudo-inverse + desaturation solution, by the QP cost."""
    INVALID_INPUT = 3
    """Non-finite command or effectiveness: previous command held (clipped to the bounds)."""
    PSEUDO_INVERSE = 4
    """Result of the baseline ``PseudoInverseAllocator`` (no QP involved)."""


@dataclass(frozen=True, slots=True)
class AllocationResult:
    """One allocation step.

    Attributes:
        u: actuator command (n_u,), normalised units, always finite and within the bounds.
        v_achieved: ``B @ u`` (n_v,), same units as ``v`` (N, N m).
        residual: ``v_achieved - v`` (n_v,); zero when the command was feasible.
        status: see ``AllocationStatus``.
        iterations: OSQP iterations (0 when OSQP did not run).
        solve_time_s: OSQP's own solve time [s] (0 when it did not run).
        wall_time_s: wall-clock time of the whole ``allocate`` call [s], Python included.
        solver_status: OSQP status string (or a short reason when OSQP did not run).
        polished: True when the active-set polish certified ``u`` as the exact optimum.
    """

    u: np.ndarray
    v_achieved: np.ndarray
    residual: np.ndarray
    status: AllocationStatus
    iterations: int
    solve_time_s: float
    wall_time_s: float
    solver_status: str
    polished: bool = False


@dataclass(slots=True)
class AllocatorStats:
    """Running statistics of an allocator (counts per status, iterations, timing)."""

    calls: int = 0
    counts: dict[AllocationStatus, int] = field(
        default_factory=lambda: dict.fromkeys(AllocationStatus, 0)
    )
    total_iterations: int = 0
    max_iterations: int = 0
    max_wall_time_s: float = 0.0
    total_wall_time_s: float = 0.0

    def record(self, res: AllocationResult) -> None:
        """Account for one result."""
        self.calls += 1
        self.counts[res.status] += 1
        self.total_iterations += res.iterations
        self.max_iterations = max(self.max_iterations, res.iterations)
        self.total_wall_time_s += res.wall_time_s
        self.max_wall_time_s = max(self.max_wall_time_s, res.wall_time_s)

    @property
    def fallbacks(self) -> int:
        """Steps that did not use a converged QP solution (fallback or invalid input)."""
        return self.counts[AllocationStatus.FALLBACK] + self.counts[AllocationStatus.INVALID_INPUT]

    @property
    def mean_iterations(self) -> float:
        """Mean OSQP iterations per call."""
        return self.total_iterations / self.calls if self.calls else 0.0

    def as_dict(self) -> dict[str, Any]:
        """Plain-dict view (status names as keys), e.g. for a metrics JSON."""
        return {
            "calls": self.calls,
            "counts": {s.name.lower(): n for s, n in self.counts.items()},
            "mean_iterations": self.mean_iterations,
            "max_iterations": self.max_iterations,
            "max_wall_time_s": self.max_wall_time_s,
            "mean_wall_time_s": self.total_wall_time_s / self.calls if self.calls else 0.0,
        }


def _as_vec(x: Any, n: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise ValueError(f"{name}: expected shape ({n},), got {a.shape}")
    return a


_F64 = np.dtype(np.float64)
_perf_counter = time.perf_counter
_OSQP_SOLVED = int(osqp.SolverStatus.OSQP_SOLVED)
_OSQP_SOLVED_INACCURATE = int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
# AllocationStatus members as module constants for the per-step path (an Enum class
# attribute costs ~75 ns in Python 3.11)
_ST_SOLVED = AllocationStatus.SOLVED
_ST_SOLVED_INACCURATE = AllocationStatus.SOLVED_INACCURATE
_ST_FALLBACK = AllocationStatus.FALLBACK
_ST_INVALID_INPUT = AllocationStatus.INVALID_INPUT


def _vec_arg(x: Any, n: int, name: str) -> np.ndarray:
    """``_as_vec`` with a fast exit for a float64 array of shape (n,) (no copy either way)."""
    if type(x) is np.ndarray and x.dtype == _F64 and x.shape == (n,):
        return x
    return _as_vec(x, n, name)


def rate_limited_bounds(
    u_min: np.ndarray,
    u_max: np.ndarray,
    u_prev: np.ndarray | None,
    rate: np.ndarray | None,
    dt: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-step bounds: position limits intersected with ``u_prev ± rate * dt``.

    Args:
        u_min, u_max: position limits (n_u,), normalised units.
        u_prev: previous actuator command (n_u,) or None (no rate limiting).
        rate: rate limits (n_u,) in normalised units per second (``inf`` = none) or None.
        dt: step [s].

    Returns:
        ``(lo, hi)`` with ``u_min <= lo <= hi <= u_max`` element-wise. Where the intersection
        is empty the position limits win and the interval collapses to the position-feasible
        point nearest to the rate-feasible interval.
    """
    if u_prev is None or rate is None:
        return u_min, u_max
    step = rate * dt
    lo = np.maximum(u_min, u_prev - step)
    hi = np.minimum(u_max, u_prev + step)
    bad = lo > hi
    if np.any(bad):
        # u_prev - step > u_max  -> lo = hi = u_max ; u_prev + step < u_min -> lo = hi = u_min
        fix = np.clip(u_prev, u_min, u_max)
        lo = np.where(bad, fix, lo)
        hi = np.where(bad, fix, hi)
    return lo, hi


class PseudoInverseAllocator:
    """PX4-style baseline: pseudo-inverse + sequential desaturation + clipping.

    ``u = u_trim + B⁺ (v - B u_trim)`` (the minimum-norm deviation from the trim actuator
    vector), then PX4's ``mixAirmodeDisabled`` / ``mixYaw`` sequence (see module docstring),
    then clipping into the limits. ``B⁺`` is recomputed only when ``B`` changes.

    Args:
        u_min, u_max: actuator position limits (n_u,).
        u_trim: trim / preferred actuator vector (n_u,); defaults to clip(0, u_min, u_max).
        thrust_axis, roll_axis, pitch_axis, yaw_axis: indices of the vertical-force (NED z,
            negative up) and moment axes in ``v`` (defaults follow ``AXES_5``). ``None``
            skips that desaturation step.
        weights_u: optional actuator weights for a weighted pseudo-inverse
            ``B⁺ = W⁻¹B'(B W⁻¹ B')⁻¹`` (all ones = PX4's plain pseudo-inverse).
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
            else _as_vec(u_trim, self.n_u, "u_trim")
        )
        self.thrust_axis = thrust_axis
        self.roll_axis = roll_axis
        self.pitch_axis = pitch_axis
        self.yaw_axis = yaw_axis
        self.weights_u = None if weights_u is None else _as_vec(weights_u, self.n_u, "weights_u")
        self._B_cached: np.ndarray | None = None
        self._pinv: np.ndarray | None = None
        self.stats = AllocatorStats()

    def pinv(self, B: np.ndarray) -> np.ndarray:
        """(Weighted) pseudo-inverse of ``B``, cached while ``B`` does not change."""
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
        """Actuator command (n_u,) clipped into ``[lo, hi]`` (defaults: position limits)."""
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
        u_trim: np.ndarray | None = None,
    ) -> AllocationResult:
        """Allocate ``v`` (n_v,) with effectiveness ``B`` (n_v x n_u); same result type as the QP.

        Non-finite input holds ``u_trim`` clipped (status ``INVALID_INPUT``).
        """
        t0 = time.perf_counter()
        v = np.asarray(v, dtype=float)
        B = np.asarray(B, dtype=float)
        lo = self.u_min if u_min is None else np.asarray(u_min, dtype=float)
        hi = self.u_max if u_max is None else np.asarray(u_max, dtype=float)
        ut = self.u_trim if u_trim is None else np.asarray(u_trim, dtype=float)
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(B)) and np.all(np.isfinite(ut))):
            u = np.clip(np.nan_to_num(self.u_trim), self.u_min, self.u_max)
            status, reason = _ST_INVALID_INPUT, "non-finite input"
        else:
            u = self.compute(v, B, lo, hi, ut)
            status, reason = AllocationStatus.PSEUDO_INVERSE, "pseudo-inverse"
        if status == _ST_INVALID_INPUT:  # report finite numbers only
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


@numba.njit(cache=True)
def _step_bounds(umin_def, umax_def, umin_in, umax_in, prev, has_prev, rate, has_rate, dt,
                 lo, hi):
    """Per-step bounds into ``lo``/``hi`` (compiled): position limits (non-finite entries of
    the per-step limits replaced by the construction ones, upper raised to the lower where
    crossed), intersected with ``prev ± rate dt`` when ``prev`` is given and finite (see
    ``rate_limited_bounds``). Returns 1 when ``prev`` is absent or finite, else 0."""
    n = lo.shape[0]
    prev_ok = 1
    if has_prev:
        for j in range(n):
            if not np.isfinite(prev[j]):
                prev_ok = 0
                break
    for j in range(n):
        pmin = umin_in[j] if np.isfinite(umin_in[j]) else umin_def[j]
        pmax = umax_in[j] if np.isfinite(umax_in[j]) else umax_def[j]
        if pmax < pmin:
            pmax = pmin
        a = pmin
        b = pmax
        if has_prev and prev_ok and has_rate:
            st = rate[j] * dt
            a = max(pmin, prev[j] - st)
            b = min(pmax, prev[j] + st)
            if a > b:
                a = min(max(prev[j], pmin), pmax)
                b = a
        lo[j] = a
        hi[j] = b
    return prev_ok


@numba.njit(cache=True)
def _prepare(v, B, pref, B_last, w_v2, reg, tri_r, tri_c, Hn, Px, BtW2s, scale, qn):
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


@numba.njit(cache=True)
def _box_qp_active_set(H, q, lo, hi, u0, max_iter, tol):
    n = q.size
    u = np.empty(n)
    state = np.zeros(n, dtype=np.int8)  # 0 free, -1 at lo, +1 at hi, 2 fixed (lo == hi)
    hscale = 0.0
    qscale = 0.0
    for i in range(n):
        hscale = max(hscale, abs(H[i, i]))
        qscale = max(qscale, abs(q[i]))
    if hscale == 0.0:
        hscale = 1.0
    tol_d = tol * (1.0 + qscale + hscale)
    for i in range(n):
        w = hi[i] - lo[i]
        snap = 1e-6 * (1.0 + w)
        ui = min(max(u0[i], lo[i]), hi[i])
        if w <= 0.0:
            state[i] = 2
            ui = lo[i]
        elif ui - lo[i] <= snap:
            state[i] = -1
            ui = lo[i]
        elif hi[i] - ui <= snap:
            state[i] = 1
            ui = hi[i]
        u[i] = ui
    g = H @ u + q
    at_min = False
    it = 0
    while it < max_iter:
        it += 1
        if not at_min:
            # Newton step on the free variables: H_FF p_F = -g_F
            nf = 0
            for i in range(n):
                if state[i] == 0:
                    nf += 1
            if nf > 0:
                idx = np.empty(nf, dtype=np.int64)
                k = 0
                for i in range(n):
                    if state[i] == 0:
                        idx[k] = i
                        k += 1
                Hff = np.empty((nf, nf))
                rhs = np.empty(nf)
                for a in range(nf):
                    rhs[a] = -g[idx[a]]
                    for b in range(nf):
                        Hff[a, b] = H[idx[a], idx[b]]
                # Cholesky (H is SPD); a non-positive pivot means failure
                L = np.zeros((nf, nf))
                for a in range(nf):
                    s = Hff[a, a]
                    for c in range(a):
                        s -= L[a, c] * L[a, c]
                    if not s > 0.0:
                        return u, False, it
                    L[a, a] = np.sqrt(s)
                    for b in range(a + 1, nf):
                        s2 = Hff[b, a]
                        for c in range(a):
                            s2 -= L[b, c] * L[a, c]
                        L[b, a] = s2 / L[a, a]
                y = np.empty(nf)
                for a in range(nf):
                    s = rhs[a]
                    for c in range(a):
                        s -= L[a, c] * y[c]
                    y[a] = s / L[a, a]
                pf = np.empty(nf)
                for a in range(nf - 1, -1, -1):
                    s = y[a]
                    for c in range(a + 1, nf):
                        s -= L[c, a] * pf[c]
                    pf[a] = s / L[a, a]
                # step length to the first blocking bound
                alpha = 1.0
                block = -1
                for a in range(nf):
                    i = idx[a]
                    if pf[a] < 0.0:
                        r = (lo[i] - u[i]) / pf[a]
                        if r < alpha:
                            alpha = r
                            block = i
                    elif pf[a] > 0.0:
                        r = (hi[i] - u[i]) / pf[a]
                        if r < alpha:
                            alpha = r
                            block = i
                if alpha < 0.0:
                    alpha = 0.0
                for a in range(nf):
                    u[idx[a]] += alpha * pf[a]
                if block < 0:
                    # full step: one iterative-refinement pass with the same factor (the
                    # reduced Hessian is badly conditioned in the rotor null space)
                    g = H @ u + q
                    for a in range(nf):
                        s = -g[idx[a]]
                        for c in range(a):
                            s -= L[a, c] * y[c]
                        y[a] = s / L[a, a]
                    for a in range(nf - 1, -1, -1):
                        s = y[a]
                        for c in range(a + 1, nf):
                            s -= L[c, a] * pf[c]
                        pf[a] = s / L[a, a]
                    for a in range(nf):
                        i = idx[a]
                        u[i] = min(max(u[i] + pf[a], lo[i]), hi[i])
                if block >= 0:
                    if pf[np.searchsorted(idx, block)] < 0.0:
                        state[block] = -1
                        u[block] = lo[block]
                    else:
                        state[block] = 1
                        u[block] = hi[block]
                else:
                    at_min = True
                g = H @ u + q
                if block >= 0:
                    continue
            at_min = True
        # at a subspace minimum: check the multipliers of the bounds held
        worst = -1
        worst_v = tol_d
        for i in range(n):
            if state[i] == -1 and -g[i] > worst_v:  # at lo, optimal iff g_i >= 0
                worst_v = -g[i]
                worst = i
            elif state[i] == 1 and g[i] > worst_v:  # at hi, optimal iff g_i <= 0
                worst_v = g[i]
                worst = i
        if worst < 0:
            # KKT: free gradient ~ 0 (checked relative), bounds held with right sign
            for i in range(n):
                if state[i] == 0 and abs(g[i]) > tol_d * 1e3:
                    return u, False, it
            return u, True, it
        state[worst] = 0
        at_min = False
    return u, False, it


def box_qp_polish(
    H: np.ndarray,
    q: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    u0: np.ndarray,
    max_iter: int = 60,
    tol: float = 1e-9,
) -> tuple[np.ndarray, bool, int]:
    """Active-set refinement ("polish") of ``min 1/2 u'Hu + q'u  s.t. lo <= u <= hi``.

    A primal active-set method (Nocedal & Wright, Numerical Optimization, alg. 16.3,
    specialised to bounds) started from an approximate solution ``u0`` (OSQP's iterate): the
    bounds that ``u0`` touches form the initial working set; Newton steps on the free
    variables (Cholesky of the reduced Hessian) either reach the subspace minimum or stop at
    the first blocking bound (added to the working set); at a subspace minimum the bound with
    the most wrongly-signed multiplier is released. When no multiplier is wrong the point
    satisfies the KKT conditions of the convex QP, i.e. it is the exact optimum. Started from
    a good OSQP iterate this takes one or two Newton steps.

    This plays the role of OSQP's own ``polishing``, which is switched off because OSQP 1.x
    prints a line to stdout on every polished solve without active bounds (osqp/osqp#785), and
    because ADMM converges slowly on these badly conditioned problems (rotor null space with
    curvature ~eps) while the active set it finds early is usually right. Compiled with numba.

    Args:
        H: symmetric positive definite Hessian (n x n).
        q: linear term (n,).
        lo, hi: bounds (n,), ``lo <= hi``.
        u0: starting point (n,), finite.
        max_iter: maximum working-set changes.
        tol: relative KKT tolerance.

    Returns:
        ``(u, ok, iterations)``; ``u`` is within the bounds; ``ok`` is True when the KKT
        conditions hold.
    """
    u, ok, it = _box_qp_active_set(H, q, lo, hi, u0, max_iter, tol)
    return u, bool(ok), int(it)  # u stays within [lo, hi] by construction


@numba.njit(cache=True)
def _polish_duals(H, q, lo, hi, x, do_polish, max_iter, tol, lam):
    """Post-solve work of one step (compiled): whether OSQP's iterate ``x`` is finite, and
    when ``do_polish`` the polish from it (``_box_qp_active_set``); when it certifies the
    optimum ``u``, the bound multipliers for the next warm start are written into ``lam``
    (``-(H u + q)`` on the bounds held, 0 on the free variables). Returns
    ``(u, x_finite, polished)``; ``u`` is ``x`` itself when not polished."""
    n = x.size
    finite = True
    for i in range(n):
        if not np.isfinite(x[i]):
            finite = False
            break
    if not (do_polish and finite):
        return x, finite, False
    u, ok, _ = _box_qp_active_set(H, q, lo, hi, x, max_iter, tol)
    if not ok:
        return x, finite, False
    g = H @ u + q
    for i in range(n):
        lam[i] = 0.0 if (u[i] > lo[i] and u[i] < hi[i]) else -g[i]
    return u, finite, True


class QPAllocator:
    """Weighted least-squares control allocation with box (and rate) limits, solved by OSQP.

    See the module docstring for the problem, the solver settings, the polish step and the
    fallback policy.

    Args:
        n_v: number of virtual axes (e.g. 5, see ``AXES_5``).
        u_min, u_max: actuator position limits (n_u,), normalised units.
        w_v: virtual-axis weights (n_v,), > 0; squared in the cost. Axis priority: e.g.
            ``[1, 1, 10, 10, 3]`` (forces in N, moments in N m) tracks roll/pitch first.
        w_u: actuator weights (n_u,) for the secondary objective (default ones).
        eps: weight of the secondary objective (default 1e-6, absolute, in the units of the
            weighted virtual command squared per actuator unit squared). A feasible command is
            met to about ``eps |u - u_pref| / sigma_min(W_v B)`` (weighted units).
        u_pref: preferred actuator vector (n_u,) (default: clip(0, u_min, u_max)).
        rate_limit: actuator rate limits (n_u,) in normalised units per second, or None.
        dt: control period [s] for the rate limits (default 1/250).
        settings: OSQP setting overrides (e.g. ``{"max_iter": 50}``).
        polish: refine OSQP's iterate with ``box_qp_polish`` (default True).
        thrust_axis, roll_axis, pitch_axis, yaw_axis: axis indices for the fallback's
            sequential desaturation (defaults follow ``AXES_5``).
        fast_path: call the OSQP extension object directly (skips the Python wrapper's
            per-call bookkeeping, about 8 us per step); falls back to the public API if the
            installed osqp does not expose it.
    """

    def __init__(
        self,
        n_v: int,
        u_min: np.ndarray,
        u_max: np.ndarray,
        *,
        w_v: np.ndarray | None = None,
        w_u: np.ndarray | None = None,
        eps: float = 1e-6,
        u_pref: np.ndarray | None = None,
        rate_limit: np.ndarray | None = None,
        dt: float = 1.0 / 250.0,
        settings: Mapping[str, Any] | None = None,
        polish: bool = True,
        thrust_axis: int | None = 0,
        roll_axis: int | None = 2,
        pitch_axis: int | None = 3,
        yaw_axis: int | None = 4,
        fast_path: bool = True,
    ) -> None:
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
        self.w_v = np.ones(n_v) if w_v is None else _as_vec(w_v, n_v, "w_v").copy()
        self.w_u = np.ones(n_u) if w_u is None else _as_vec(w_u, n_u, "w_u").copy()
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
            else _as_vec(u_pref, n_u, "u_pref").copy()
        )
        if not np.all(np.isfinite(self.u_pref)):
            raise ValueError("u_pref must be finite")
        if rate_limit is not None:
            rate_limit = _as_vec(rate_limit, n_u, "rate_limit").copy()
            if np.any(rate_limit <= 0) or np.any(np.isnan(rate_limit)):
                raise ValueError("rate_limit must be > 0 (inf = unlimited)")
        self.rate_limit = rate_limit
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.dt = float(dt)
        self.polish = bool(polish)

        self.settings: dict[str, Any] = dict(_DEFAULT_OSQP_SETTINGS)
        if settings:
            self.settings.update(settings)

        self._baseline = PseudoInverseAllocator(
            self.u_min,
            self.u_max,
            u_trim=self.u_pref,
            thrust_axis=thrust_axis,
            roll_axis=roll_axis,
            pitch_axis=pitch_axis,
            yaw_axis=yaw_axis,
        )

        # Upper triangle of the dense n_u x n_u P, in CSC (column-major) order.
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

        self._prob: osqp.OSQP | None = None
        self._solver: Any = None
        self._fast_path = fast_path
        self._u_last: np.ndarray | None = None
        self.stats = AllocatorStats()

    # ------------------------------------------------------------------------------------
    def reset(self, u0: np.ndarray | None = None) -> None:
        """Forget the previous command and the solver state (warm start); optionally set it."""
        self._u_last = None if u0 is None else _as_vec(u0, self.n_u, "u0").copy()
        self._prob = None
        self._solver = None
        self._B_last.fill(np.nan)

    @property
    def u_last(self) -> np.ndarray | None:
        """Previous allocated command (n_u,), or None before the first step."""
        return None if self._u_last is None else self._u_last.copy()

    def cost(
        self, u: np.ndarray, v: np.ndarray, B: np.ndarray, u_pref: np.ndarray | None = None
    ) -> float:
        """QP objective ``||W_v (B u - v)||² + eps ||W_u (u - u_pref)||²``."""
        r = self.w_v * (B @ u - v)
        d = self.w_u * (u - (self.u_pref if u_pref is None else u_pref))
        return float(r @ r + self.eps * (d @ d))

    def tracking_cost(self, u: np.ndarray, v: np.ndarray, B: np.ndarray) -> float:
        """Weighted tracking error ``||W_v (B u - v)||²`` (the primary objective)."""
        r = self.w_v * (B @ u - v)
        return float(r @ r)

    # ------------------------------------------------------------------------------------
    def _setup(self, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        P = sp.csc_matrix(
            (self._Px.copy(), self._tri_r.astype(np.int64), self._P_indptr),
            shape=(self.n_u, self.n_u),
        )
        prob = osqp.OSQP()
        prob.setup(P, q, sp.identity(self.n_u, format="csc"), lo, hi, **self.settings)
        self._prob = prob
        solver = getattr(prob, "_solver", None)
        ok = (
            self._fast_path
            and solver is not None
            and all(hasattr(solver, a) for a in ("update_data_vec", "update_data_mat", "solve"))
        )
        self._solver = solver if ok else None

    def _warm_start(self, x: np.ndarray, y: np.ndarray) -> None:
        if self._prob is None or not self.settings.get("warm_starting", True):
            return
        if self._solver is not None:
            self._solver.warm_start(x, y)
        else:
            self._prob.warm_start(x=x, y=y)

    def _run_osqp(
        self, q: np.ndarray, lo: np.ndarray, hi: np.ndarray, B_changed: bool
    ) -> tuple[np.ndarray, str, int, int, float]:
        """Update the data and solve; returns (x, status string, status value, iter, time)."""
        s = self._solver
        if self._prob is None:
            self._setup(q, lo, hi)
            s = self._solver
            if self._u_last is not None:
                self._warm_start(np.clip(self._u_last, lo, hi), self._zeros_u)
        elif s is not None:
            s.update_data_vec(q, lo, hi)  # (q, l, u), positional: cheaper through pybind11
            if B_changed:
                s.update_data_mat(P_x=self._Px, P_i=None, A_x=None, A_i=None)
        elif B_changed:
            self._prob.update(q=q, l=lo, u=hi, Px=self._Px.copy())
        else:
            self._prob.update(q=q, l=lo, u=hi)
        if s is not None:
            s.solve()
            info = s.info
            x = s.solution.x  # a new array per call; only read before the next solve
            if type(x) is not np.ndarray or x.dtype != _F64:
                x = np.array(x, dtype=float)
            return x, info.status, info.status_val, info.iter, info.solve_time
        res = self._prob.solve(raise_error=False)
        info = res.info
        x = np.array(res.x, dtype=float)
        return x, info.status, int(info.status_val), int(info.iter), float(info.solve_time)

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

        Args:
            v: virtual command (n_v,) [N, N m].
            B: effectiveness (n_v x n_u) [N or N m per normalised unit]; may change every step.
            u_min, u_max: per-step position limits (n_u,), default the construction limits
                (e.g. narrowed by a flight mode); non-finite entries fall back to those.
            u_pref: per-step preferred actuator vector (n_u,), default the construction one.
            u_prev: actuator state for the rate limits (n_u,), default the previous result.

        Returns:
            ``AllocationResult``; ``u`` is finite and within the (rate-limited) bounds.
        """
        t0 = _perf_counter()
        n_u = self.n_u
        # float64 ndarrays of the right shape (the autopilot's case) pass without copies
        if type(v) is not np.ndarray or v.dtype != _F64:
            v = np.asarray(v, dtype=float)
        if type(B) is not np.ndarray or B.dtype != _F64:
            B = np.asarray(B, dtype=float)
        if v.shape != (self.n_v,):
            raise ValueError(f"v: expected shape ({self.n_v},), got {v.shape}")
        if B.shape != (self.n_v, n_u):
            raise ValueError(f"B: expected shape ({self.n_v}, {n_u}), got {B.shape}")

        # Per-step bounds (compiled; same result as _sane_limit + rate_limited_bounds).
        umin_in = self.u_min if u_min is None else _vec_arg(u_min, n_u, "u_min")
        umax_in = self.u_max if u_max is None else _vec_arg(u_max, n_u, "u_max")
        prev = self._u_last if u_prev is None else _vec_arg(u_prev, n_u, "u_prev")
        lo = np.empty(n_u)
        hi = np.empty(n_u)
        rate = self.rate_limit
        prev_ok = _step_bounds(
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
        pref = self.u_pref if u_pref is None else _vec_arg(u_pref, n_u, "u_pref")
        code = -1
        if prev_ok:
            code = _prepare(
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
                _ST_INVALID_INPUT,
                0,
                0.0,
                t0,
                "non-finite input",
                False,
            )
        B_changed = code == 1
        qn = self._qn

        try:
            x, st_str, st_val, iters, t_solve = self._run_osqp(qn, lo, hi, B_changed)
        except Exception as exc:  # OSQP raised (setup/update/solve error): fall back
            x, st_str, st_val, iters, t_solve = (
                np.full(n_u, np.nan),
                f"exception: {exc!r}",
                -1,
                0,
                0.0,
            )
            self._prob = None  # set the solver up again next step
            self._solver = None

        # finiteness check, polish and (when polished) the warm-start duals in one compiled
        # call: λ = -(Hn u + qn) on the bounds held, 0 on the free variables
        lam = np.empty(n_u)
        u, x_finite, polished = _polish_duals(self._Hn, qn, lo, hi, x, self.polish, 60, 1e-9,
                                              lam)
        if polished:
            status = _ST_SOLVED  # KKT-certified optimum
        elif st_val == _OSQP_SOLVED and x_finite:
            u = np.clip(x, lo, hi)
            status = _ST_SOLVED
        elif st_val == _OSQP_SOLVED_INACCURATE and x_finite:
            u = np.clip(x, lo, hi)
            status = _ST_SOLVED_INACCURATE
        else:
            u = self._baseline.compute(v, B, lo, hi, pref)
            if x_finite:
                u_it = np.clip(x, lo, hi)
                if self.cost(u_it, v, B, pref) < self.cost(u, v, B, pref):
                    u = u_it
            status = _ST_FALLBACK
            lam = -(self._Hn @ u + qn)
            lam[(u > lo) & (u < hi)] = 0.0
        if polished or status == _ST_FALLBACK:
            # restart the next ADMM solve from the returned point (duals: λ = -(Hn u + qn))
            try:
                self._warm_start(u, lam)
            except Exception:
                self._prob = None
                self._solver = None
        return self._finish(u, v, B, status, iters, t_solve, t0, st_str, polished)

    @staticmethod
    def _sane_limit(x: Any, default: np.ndarray, name: str) -> np.ndarray:
        a = _as_vec(x, default.size, name)
        if np.all(np.isfinite(a)):
            return a
        return np.where(np.isfinite(a), a, default)

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
        if status == _ST_INVALID_INPUT:  # report finite numbers only
            B = np.nan_to_num(B, nan=0.0, posinf=0.0, neginf=0.0)
            v = np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0)
        va = B @ u
        self._u_last = u
        res = _new_result(u, va, va - v, status, iters, t_solve, _perf_counter() - t0, st_str,
                          polished)
        self.stats.record(res)
        return res


_AR_FIELDS = ("u", "v_achieved", "residual", "status", "iterations", "solve_time_s",
              "wall_time_s", "solver_status", "polished")
(_set_u, _set_va, _set_res, _set_status, _set_iter, _set_solve, _set_wall, _set_str,
 _set_pol) = (AllocationResult.__dict__[f].__set__ for f in _AR_FIELDS)


def _new_result(u: np.ndarray, va: np.ndarray, res: np.ndarray, status: AllocationStatus,
                iters: int, t_solve: float, t_wall: float, st_str: str,
                polished: bool) -> AllocationResult:
    """``AllocationResult(...)`` (same fields, same order) without the frozen dataclass's
    per-field ``object.__setattr__`` round trips: about 1 us less per step."""
    r = object.__new__(AllocationResult)
    _set_u(r, u)
    _set_va(r, va)
    _set_res(r, res)
    _set_status(r, status)
    _set_iter(r, iters)
    _set_solve(r, t_solve)
    _set_wall(r, t_wall)
    _set_str(r, st_str)
    _set_pol(r, polished)
    return r
