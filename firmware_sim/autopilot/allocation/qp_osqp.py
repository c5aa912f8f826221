"""QP allocation with OSQP (ADMM), finished by the compiled active-set solver ("polish").

Not the allocator that flies (that is ``active_set.ActiveSetAllocator``): kept as the
independent comparison of the tests and benchmarks, with the same API. OSQP is an optional
dependency (``pip install "vtol-ftc[osqp]"``; the ``test`` extra includes it): without it this
module imports and :class:`QPAllocator` raises ``ImportError`` with that hint.

Solves the problem of ``wls`` every control step with OSQP through its public Python API, in
the OSQP form ``min 1/2 u'P u + q'u  s.t.  l <= A u <= h`` with ``P = Hn`` (dense upper
triangle, fixed sparsity pattern), ``q = qn``, ``A = I``. ``B`` may change every step
(airspeed-dependent surface effectiveness): only the numerical values of ``P`` are updated in
place (same sparsity pattern, no new setup, and no update at all when ``B`` is bit-identical to
the previous step); ``q`` and the bounds are updated every step. OSQP is warm-started from the
previous step's solution (primal and dual).

Polish: ADMM converges slowly on this problem (the rotor null space has curvature ~eps, the
moment rows ~1), but it identifies the active bounds early. OSQP's own ``polishing`` is off
(OSQP 1.x prints a line to stdout on every polished solve without active bounds, osqp/osqp#785);
instead ``active_set.box_qp`` (a compiled primal active-set method started from OSQP's
iterate) finishes the job. ``AllocationResult.polished`` says when its optimality test passed;
the status is then ``SOLVED`` even if ADMM itself stopped at its iteration limit
(``solver_status`` keeps OSQP's own word). What that test guarantees, in command units, is
stated in ``active_set``: the achieved ``B u`` and the cost are accurate, the split of the
command among redundant actuators only to ~4e-5 (measured on case 1; the 1e-9 tolerance alone
would allow far more, OSQP's iterate being close is what keeps it there). With
``polish=False`` the allocator relies on OSQP alone (its own ``eps_abs``/``eps_rel`` test).

Solver settings (overridable through ``settings=``): ``eps_abs = eps_rel = 1e-5`` (on the
normalised problem), ``max_iter = 80``, ``check_termination = 5``, ``polishing = False`` (see
above), ``adaptive_rho`` on, warm starting on, and no wall-clock time limit (OSQP's default
``time_limit``, 1e10 s), so a run is deterministic: OSQP stops at its tolerance or at
``max_iter``. See ``benchmarks/bench_allocation.py`` for the measured cost.

The returned ``u`` is always clipped into ``[lo, hi]`` (OSQP meets the bounds only to its
tolerance), so limits are never violated. When neither the polish passes nor OSQP reports
``solved``/``solved inaccurate`` the allocator falls back (``wls``); OSQP is then warm-started
from the returned ``u``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Unpack

import numba
import numpy as np
import scipy.sparse as sp

try:
    import osqp
except ImportError:  # optional: pip install "vtol-ftc[osqp]"
    osqp = None

from vtolftc.firmware_sim.autopilot.allocation.active_set import box_qp_active_set
from vtolftc.firmware_sim.autopilot.allocation.interface import AllocationResult
from vtolftc.firmware_sim.autopilot.allocation.wls import (
    F64,
    ST_FALLBACK,
    ST_SOLVED,
    ST_SOLVED_INACCURATE,
    ProblemOptions,
    WLSAllocator,
)

__all__ = ["QPAllocator"]

_DEFAULT_OSQP_SETTINGS: dict[str, Any] = {
    "verbose": False,
    "eps_abs": 1e-5,
    "eps_rel": 1e-5,
    "eps_prim_inf": 1e-6,
    "eps_dual_inf": 1e-6,
    "max_iter": 80,
    "check_termination": 5,
    "polishing": False,  # see the module docstring
    "adaptive_rho": True,
    "warm_starting": True,
    "scaling": 10,
}
_OSQP_SOLVED = int(osqp.SolverStatus.OSQP_SOLVED) if osqp is not None else 1
_OSQP_SOLVED_INACCURATE = (int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE) if osqp is not None
                           else 2)


@numba.njit(cache=True)
def _polish_duals(H, q, lo, hi, x, do_polish, max_iter, tol, lam):
    """Post-solve work of one step (compiled): whether OSQP's iterate ``x`` is finite, and
    when ``do_polish`` the active-set solve from it; when its test passes on ``u``, the bound
    multipliers for the next warm start are written into ``lam`` (``-(H u + q)`` on the bounds
    held, 0 on the free variables). Returns ``(u, x_finite, polished)``; ``u`` is ``x`` itself
    when not polished."""
    n = x.size
    finite = True
    for i in range(n):
        if not np.isfinite(x[i]):
            finite = False
            break
    if not (do_polish and finite):
        return x, finite, False
    u, ok, _ = box_qp_active_set(H, q, lo, hi, x, max_iter, tol)
    if not ok:
        return x, finite, False
    g = H @ u + q
    for i in range(n):
        lam[i] = 0.0 if (u[i] > lo[i] and u[i] < hi[i]) else -g[i]
    return u, finite, True


class QPAllocator(WLSAllocator):
    """Weighted least-squares control allocation with box (and rate) limits: OSQP + polish.

    See the module docstring for the solver, its settings and the polish, and ``wls`` for the
    problem, the invalid-input hold and the fallback.

    Parameters
    ----------
    n_v, u_min, u_max, **options
        The problem, see ``wls.WLSAllocator`` (options: ``wls.ProblemOptions``).
    settings : Mapping, optional
        OSQP setting overrides (e.g. ``{"max_iter": 50}``, ``{"time_limit": 1e-3}`` [s]).
    polish : bool
        Refine OSQP's iterate with the active-set solver (default True).
    polish_tol : float
        Relative KKT tolerance of the polish (default 1e-9, see ``active_set.box_qp``).
    """

    def __init__(self, n_v: int, u_min: np.ndarray, u_max: np.ndarray, *,
                 settings: Mapping[str, Any] | None = None, polish: bool = True,
                 polish_tol: float = 1e-9, **options: Unpack[ProblemOptions]) -> None:
        if osqp is None:
            raise ImportError("QPAllocator needs OSQP: pip install \"vtol-ftc[osqp]\" (the "
                              "allocator that flies, ActiveSetAllocator, does not)")
        super().__init__(n_v, u_min, u_max, **options)
        self.polish = bool(polish)
        self.polish_tol = float(polish_tol)
        self.settings: dict[str, Any] = dict(_DEFAULT_OSQP_SETTINGS)
        if settings:
            self.settings.update(settings)
        self._prob: osqp.OSQP | None = None

    def reset(self, u0: np.ndarray | None = None) -> None:
        """Forget the previous command and the OSQP state (warm start); optionally set the
        previous command to ``u0`` (n_u,)."""
        super().reset(u0)
        self._prob = None

    # ------------------------------------------------------------------------------------
    def _setup(self, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        P = sp.csc_matrix(
            (self._Px.copy(), self._tri_r.astype(np.int64), self._P_indptr),
            shape=(self.n_u, self.n_u),
        )
        prob = osqp.OSQP()
        prob.setup(P, q, sp.identity(self.n_u, format="csc"), lo, hi, **self.settings)
        self._prob = prob

    def _warm_start(self, x: np.ndarray, y: np.ndarray) -> None:
        if self._prob is None or not self.settings.get("warm_starting", True):
            return
        self._prob.warm_start(x=x, y=y)

    def _run_osqp(
        self, q: np.ndarray, lo: np.ndarray, hi: np.ndarray, B_changed: bool
    ) -> tuple[np.ndarray, str, int, int, float]:
        """Update the data and solve; returns (x, status string, status value, iter, time)."""
        if self._prob is None:
            self._setup(q, lo, hi)
            if self._u_last is not None:
                self._warm_start(np.clip(self._u_last, lo, hi), self._zeros_u)
        elif B_changed:
            self._prob.update(q=q, l=lo, u=hi, Px=self._Px.copy())
        else:
            self._prob.update(q=q, l=lo, u=hi)
        res = self._prob.solve(raise_error=False)
        info = res.info
        x = res.x  # a new array per call; only read before the next solve
        if type(x) is not np.ndarray or x.dtype != F64:
            x = np.array(x, dtype=float)
        return x, info.status, int(info.status_val), int(info.iter), float(info.solve_time)

    def _solve(self, v: np.ndarray, B: np.ndarray, pref: np.ndarray, lo: np.ndarray,
               hi: np.ndarray, B_changed: bool, t0: float) -> AllocationResult:
        n_u = self.n_u
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

        # finiteness check, polish and (when polished) the warm-start duals in one compiled
        # call: λ = -(Hn u + qn) on the bounds held, 0 on the free variables
        lam = np.empty(n_u)
        u, x_finite, polished = _polish_duals(self._Hn, qn, lo, hi, x, self.polish, 60,
                                              self.polish_tol, lam)
        if polished:
            status = ST_SOLVED  # the active-set optimality test passed
        elif st_val == _OSQP_SOLVED and x_finite:
            u = np.clip(x, lo, hi)
            status = ST_SOLVED
        elif st_val == _OSQP_SOLVED_INACCURATE and x_finite:
            u = np.clip(x, lo, hi)
            status = ST_SOLVED_INACCURATE
        else:
            u = self._fallback(v, B, lo, hi, pref, x if x_finite else None)
            status = ST_FALLBACK
            lam = -(self._Hn @ u + qn)
            lam[(u > lo) & (u < hi)] = 0.0
        if polished or status == ST_FALLBACK:
            # restart the next ADMM solve from the returned point (duals: λ = -(Hn u + qn))
            try:
                self._warm_start(u, lam)
            except Exception:
                self._prob = None
        return self._finish(u, v, B, status, iters, t_solve, t0, st_str, polished)
