"""The allocation interface: result, status, statistics, per-step bounds, the ``Allocator``
protocol.

Every allocator of this package maps a virtual command ``v`` (n_v,) onto the actuators ``u``
(n_u,) with ``B u ≈ v`` through ``allocate(v, B, ...) -> AllocationResult`` and forgets its
state through ``reset``. This module holds what they share and nothing algorithm-specific (the
effectiveness ``B(V)`` is ``vtolftc.firmware_sim.autopilot.effectiveness``; one file per
algorithm sits beside this one), as PX4 splits ``ControlAllocation`` (interface),
``ControlAllocationPseudoInverse`` / ``...SequentialDesaturation`` (algorithms) and
``ActuatorEffectiveness`` (B).

Conventions: virtual command ``v`` in SI (forces in N, NED/FRD, so a negative vertical force
is upwards; moments in N m about the FRD body axes); ``u`` normalised (rotors 0..1, surfaces
-1..1, whatever the caller's ``B`` assumes). The default axis layout is ``AXES_5``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numba
import numpy as np

__all__ = [
    "AXES_5",
    "AllocationResult",
    "AllocationStatus",
    "Allocator",
    "AllocatorStats",
    "shortfall_mask",
    "step_bounds",
]

#: Default virtual-axis layout: vertical force (N, NED z), forward force (N), roll, pitch and
#: yaw moments (N m, FRD).
AXES_5: tuple[str, ...] = ("fz", "fx", "roll", "pitch", "yaw")


class AllocationStatus(enum.IntEnum):
    """Outcome of one allocation step."""

    SOLVED = 0
    """The QP solver met its optimality test (see the allocator for what that guarantees);
    ``u`` is its answer clipped into the bounds."""
    SOLVED_INACCURATE = 1
    """OSQP reported 'solved inaccurate' (looser tolerance); its clipped solution is used."""
    FALLBACK = 2
    """The QP solver failed (iteration limit, numerical error, exception): the best of its
    clipped iterate and the pseudo-inverse + desaturation solution, by the QP cost."""
    INVALID_INPUT = 3
    """Non-finite command or effectiveness: previous command held (clipped to the bounds)."""
    PSEUDO_INVERSE = 4
    """Result of the baseline ``PseudoInverseAllocator`` (no QP involved)."""


@dataclass(frozen=True, slots=True)
class AllocationResult:
    """One allocation step.

    Attributes
    ----------
    u : numpy.ndarray
        Actuator command (n_u,), normalised units, always finite and within the bounds.
    v_achieved : numpy.ndarray
        ``B @ u`` (n_v,), same units as ``v`` (N, N m; NED/FRD).
    residual : numpy.ndarray
        ``v_achieved - v`` (n_v,); zero (to the solver's accuracy) when ``v`` is feasible.
    status : AllocationStatus
        See ``AllocationStatus``.
    iterations : int
        Solver iterations (OSQP ADMM iterations, or working-set changes of the active-set
        solver; 0 when no iterative solver ran).
    solve_time_s : float
        The QP solver's own solve time [s] as it reports it (0 when not reported).
    wall_time_s : float
        Wall-clock time of the whole ``allocate`` call [s], Python included.
    solver_status : str
        The solver's status string (or a short reason when no solver ran).
    polished : bool
        True when the active-set solver's optimality test passed on the returned ``u``
        (for ``QPAllocator``: after refining OSQP's iterate).
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
    """Running statistics of an allocator (counts per status, iterations, timing).

    Attributes
    ----------
    calls : int
        ``allocate`` calls recorded.
    counts : dict
        Calls per ``AllocationStatus``.
    total_iterations, max_iterations : int
        Sum and maximum of ``AllocationResult.iterations``.
    max_wall_time_s, total_wall_time_s : float
        Maximum and sum of ``AllocationResult.wall_time_s`` [s].
    """

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
        """Mean solver iterations per call."""
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


@runtime_checkable
class Allocator(Protocol):
    """What the autopilot needs from an allocator.

    Attributes
    ----------
    n_u : int
        Number of actuators.
    stats : AllocatorStats
        Running statistics, updated by every ``allocate`` call.
    """

    n_u: int
    stats: AllocatorStats

    def allocate(
        self,
        v: np.ndarray,
        B: np.ndarray,
        *,
        u_min: np.ndarray | None = None,
        u_max: np.ndarray | None = None,
        u_pref: np.ndarray | None = None,
    ) -> AllocationResult:
        """Allocate ``v`` (n_v,) [N, N m] with effectiveness ``B`` (n_v x n_u) [N or N m per
        normalised unit]; per-step limits and preferred vector (n_u,) default to the
        construction ones. The returned ``u`` is finite and within the limits."""
        ...

    def reset(self, u0: np.ndarray | None = None) -> None:
        """Forget the previous command and any solver state; optionally set the previous
        command to ``u0`` (n_u,)."""
        ...


# -- helpers shared by the algorithms (not part of the public surface) ----------------------
_F64 = np.dtype(np.float64)


def as_vec(x: Any, n: int, name: str) -> np.ndarray:
    """``x`` as a float64 vector of shape (n,) (a scalar is broadcast); ValueError otherwise."""
    a = np.asarray(x, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise ValueError(f"{name}: expected shape ({n},), got {a.shape}")
    return a


def vec_arg(x: Any, n: int, name: str) -> np.ndarray:
    """``as_vec`` with a fast exit for a float64 array of shape (n,) (no copy either way)."""
    if type(x) is np.ndarray and x.dtype == _F64 and x.shape == (n,):
        return x
    return as_vec(x, n, name)


@numba.njit(cache=True)
def step_bounds(umin_def, umax_def, umin_in, umax_in, prev, has_prev, rate, has_rate, dt,
                lo, hi):
    """Per-step actuator bounds: position limits intersected with the rate limits (compiled).

    Position limits are ``umin_in``/``umax_in`` with non-finite entries replaced by the
    construction limits ``umin_def``/``umax_def`` (an upper limit below the lower one is
    raised to it). When ``has_prev`` and ``has_rate`` and ``prev`` is finite they are
    intersected with ``prev ± rate * dt``. Position limits always win: where that
    intersection is empty (the previous command lies more than one rate step outside the
    position limits, e.g. after a limit change) the interval collapses to the position-feasible
    value nearest to ``prev``, so the QP is always feasible.

    Parameters
    ----------
    umin_def, umax_def : numpy.ndarray
        Construction position limits (n_u,), finite, normalised units.
    umin_in, umax_in : numpy.ndarray
        This step's position limits (n_u,); non-finite entries mean "construction limit".
    prev : numpy.ndarray
        Previous actuator command (n_u,) (ignored unless ``has_prev``).
    has_prev : bool
        Whether ``prev`` is given.
    rate : numpy.ndarray
        Rate limits (n_u,) [normalised units / s], ``inf`` = none (ignored unless
        ``has_rate``).
    has_rate : bool
        Whether rate limits apply.
    dt : float
        Control period [s].
    lo, hi : numpy.ndarray
        Output (n_u,): ``umin <= lo <= hi <= umax`` element-wise.

    Returns
    -------
    int
        1 when ``prev`` is absent or finite, 0 when it has a non-finite entry (then the rate
        limits are not applied).
    """
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
def shortfall_mask(v, va, first, atol, rtol):
    """Which components of a command an allocation fell short of, as a bit mask (compiled;
    the same expressions in Python give the same bits).

    Component ``i`` of the ``m`` from ``first`` on (``v[first + i]``, ``i < m``) is short
    upwards when ``v > va + tol`` (bit ``i``) and downwards when ``v < va - tol`` (bit
    ``m + i``), with ``tol = atol + rtol |v|``.

    Parameters
    ----------
    v, va : numpy.ndarray
        Commanded and achieved virtual command (n_v,) [N, N m].
    first : int
        Index of the first component checked; the rest of ``v`` from there is checked.
    atol, rtol : float
        Absolute [units of ``v``] and relative tolerance.

    Returns
    -------
    int
        The mask (0: nothing short).
    """
    m = v.shape[0] - first
    mask = 0
    for i in range(m):
        w = v[first + i]
        g = va[first + i]
        tol = atol + rtol * abs(w)
        if w > g + tol:
            mask |= 1 << i
        if w < g - tol:
            mask |= 1 << (m + i)
    return mask


_AR_FIELDS = ("u", "v_achieved", "residual", "status", "iterations", "solve_time_s",
              "wall_time_s", "solver_status", "polished")
(_set_u, _set_va, _set_res, _set_status, _set_iter, _set_solve, _set_wall, _set_str,
 _set_pol) = (AllocationResult.__dict__[f].__set__ for f in _AR_FIELDS)


def new_result(u: np.ndarray, va: np.ndarray, res: np.ndarray, status: AllocationStatus,
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
