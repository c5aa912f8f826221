"""Compiled primal active-set solver of the box-constrained QP, and the allocator built on it.

``box_qp`` solves ``min 1/2 u'Hu + q'u  s.t.  lo <= u <= hi`` (H symmetric positive definite):
a primal active-set method (Nocedal & Wright, Numerical Optimization, alg. 16.3, specialised
to bounds) started from a point ``u0``. The bounds that ``u0`` touches form the initial working
set; Newton steps on the free variables (Cholesky of the reduced Hessian, one pass of iterative
refinement) either reach the subspace minimum or stop at the first blocking bound (added to the
working set); at a subspace minimum the bound with the most wrongly-signed multiplier is
released. It stops when no multiplier is wrong by more than the tolerance. Started from a
good point (OSQP's iterate, or the previous control step's command) this takes one to a few
Newton steps. Compiled with numba.

What the optimality test guarantees. With ``tol`` the relative tolerance, the test accepts a
point whose bound multipliers are wrongly signed by at most ``tau = tol (1 + max|q| + max
H_ii)`` and whose free gradient is at most ``1e3 tau``. On the normalised allocation problem
(``wls``: max H_ii = 1, |q| ~ 1) ``tau`` ~ 3 tol. The curvature of that problem is ~1 along the
directions that change ``B u``, but only ``c eps w_u²`` (~5e-12 for DS-1: ``c`` ~ 5e-6,
``eps`` = 1e-6) along the null space of ``B`` (thrust moved among the eight lift rotors, yaw
moved between differential pusher thrust and rudders). A bound held with a multiplier
``-tau`` may therefore sit up to ``tau / (c eps)`` from the optimum along that null space:

- ``tol = 1e-9`` (the polish's): ``tau / (c eps)`` ~ 600, i.e. the test says nothing about the
  split among redundant actuators (the box caps it). Started from the previous command it
  "certifies" answers 4.3e-2 away from the optimum (cost 1.3 % above it) on case 1, and from
  ``u_pref`` on a feasible low-speed command (``tests/test_allocation.py``) it held one lift
  rotor at 1 and another at 0, with ``B u`` exact.
  Started from OSQP's iterate (``QPAllocator``), which is already close, it stays within
  3.9e-5 (4.9e-3 on four ground steps where the two answers' costs tie to rounding).
- ``tol = 1e-15`` (``ActiveSetAllocator``'s default): ``tau / (c eps)`` ~ 6e-4 in a normalised
  command, near the floor set by rounding in ``g = H u + q`` (~1e-16 / 5e-12 ~ 2e-5).
  Measured on all 9,750 QPs of case 1 (``benchmarks/bench_allocation.py``) against scipy's BVLS
  at 1e-14: within 3.7e-5 wherever its cost is above the reference's, ``B u`` within 5e-10
  N / N m, cost at most 3.3e-9 (relative) above the reference.

So a passed test certifies a KKT point to that tolerance: ``B u`` and the cost accurately,
the split among redundant actuators only to the figures above, not the exact optimum.

``ActiveSetAllocator`` flies this solver alone on the ``wls`` problem, warm-started from the
previous command.
"""

from __future__ import annotations

import time
from typing import Any, Unpack

import numba
import numpy as np

from vtolftc.firmware_sim.autopilot.allocation.interface import (
    AllocationResult,
    new_result,
    shortfall_mask,
    step_bounds,
    vec_arg,
)
from vtolftc.firmware_sim.autopilot.allocation.wls import (
    F64,
    ST_FALLBACK,
    ST_INVALID_INPUT,
    ST_SOLVED,
    ProblemOptions,
    WLSAllocator,
    prepare_wls,
)
from vtolftc.firmware_sim.autopilot.control_kernels import (
    W_OUT,
    W_SIZE,
    scheduled_ppid3_step_packed,
)

__all__ = ["ActiveSetAllocator", "box_qp"]

_perf_counter = time.perf_counter
_NO_TAIL = np.empty(0)  # allocate_tracked's default v_tail: nothing copied into v


# one compiled loop the JIT optimises as a whole: splitting it would cost calls per iteration
@numba.njit(cache=True)
def box_qp_active_set(H, q, lo, hi, u0, max_iter, tol):  # noqa: C901
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



@numba.njit(cache=True)
def _allocate_step(v, B, pref, umin_def, umax_def, umin_in, umax_in, prev, has_prev, rate,
                   has_rate, dt, lo, hi, B_last, w_v2, reg, tri_r, tri_c, Hn, Px, BtW2s, scale,
                   qn, u0, max_iter, tol, u_out):
    """``step_bounds``, ``prepare_wls`` and ``box_qp_active_set`` of one allocation step in one
    compiled call (the same functions, so the same bits, without two Python round trips).

    Returns ``(code, ok, iterations)``: ``code`` -1 for non-finite input (nothing was solved,
    ``u_out`` untouched), else ``prepare_wls``'s 0 / 1 (``B`` unchanged / changed) and the
    solution in ``u_out`` (a fresh array of the caller's: no array is boxed on return);
    ``lo``/``hi`` are written in every case.
    """
    prev_ok = step_bounds(umin_def, umax_def, umin_in, umax_in, prev, has_prev, rate,
                          has_rate, dt, lo, hi)
    if not prev_ok:
        return -1, False, 0
    code = prepare_wls(v, B, pref, B_last, w_v2, reg, tri_r, tri_c, Hn, Px, BtW2s, scale, qn)
    if code < 0:
        return -1, False, 0
    u, ok, it = box_qp_active_set(Hn, qn, lo, hi, u0, max_iter, tol)
    u_out[:] = u
    return code, ok, it




@numba.njit(cache=True)
def _allocate_step_packed(v, B, pref, umin_def, umax_def, umin_in, umax_in, prev, has_prev,
                          rate, has_rate, dt, ws, iws, u0, max_iter, tol, u_out):
    """:func:`_allocate_step` with the allocator's own arrays packed into one float64
    workspace ``ws`` and one int64 array ``iws`` (see ``ActiveSetAllocator._pack``): the same
    kernels on views of the same numbers, hence the same bits, with 11 arrays fewer to unbox
    per call (each array argument of a compiled call costs its own type check and unboxing,
    about as much as the QP update itself on a step whose ``B`` did not change).

    ``ws`` holds, in order, ``lo``, ``hi`` (n_u each, written), ``B_last`` (n_v x n_u),
    ``w_v2`` (n_v), ``reg`` (n_u), ``Hn`` (n_u x n_u), ``Px`` (n_u (n_u + 1) / 2), ``BtW2s``
    (n_u x n_v), ``scale`` (1) and ``qn`` (n_u); ``iws`` holds ``tri_r`` then ``tri_c``.
    """
    n_v, n_u = B.shape
    n_t = n_u * (n_u + 1) // 2
    o = 0
    lo = ws[o:o + n_u]
    o += n_u
    hi = ws[o:o + n_u]
    o += n_u
    B_last = ws[o:o + n_v * n_u].reshape((n_v, n_u))
    o += n_v * n_u
    w_v2 = ws[o:o + n_v]
    o += n_v
    reg = ws[o:o + n_u]
    o += n_u
    Hn = ws[o:o + n_u * n_u].reshape((n_u, n_u))
    o += n_u * n_u
    Px = ws[o:o + n_t]
    o += n_t
    BtW2s = ws[o:o + n_u * n_v].reshape((n_u, n_v))
    o += n_u * n_v
    scale = ws[o:o + 1]
    o += 1
    qn = ws[o:o + n_u]
    tri_r = iws[0:n_t]
    tri_c = iws[n_t:2 * n_t]
    return _allocate_step(v, B, pref, umin_def, umax_def, umin_in, umax_in, prev, has_prev,
                          rate, has_rate, dt, lo, hi, B_last, w_v2, reg, tri_r, tri_c, Hn, Px,
                          BtW2s, scale, qn, u0, max_iter, tol, u_out)


@numba.njit(cache=True)
def _allocate_step_trusted(v, B, pref, umax_in, cst, has_prev, has_rate, dt, ws, iws, ubuf,
                           max_iter, tol):
    """:func:`_allocate_step_packed` as ``ActiveSetAllocator.allocate_trusted`` calls it, on
    8 arrays instead of 13 (each array argument of a compiled call costs its own type check
    and unboxing, ~0.15-0.2 us on this machine): the construction limits and rate limits are
    the rows of ``cst`` (``u_min``, ``u_max``, ``rate_limit``; this step's lower limits are
    the construction ones), and ``ubuf`` is at once the previous command (read first, by
    the bounds and as the warm start, when ``has_prev``; else the warm start is ``pref``)
    and the output (written last). The same kernels on the same numbers: the same bits.
    """
    umin = cst[0]
    umax = cst[1]
    rate = cst[2]
    u0 = ubuf if has_prev else pref
    return _allocate_step_packed(v, B, pref, umin, umax, umin, umax_in, ubuf, has_prev, rate,
                                 has_rate, dt, ws, iws, u0, max_iter, tol, ubuf)


@numba.njit(cache=True)
def _allocate_step_tracked(v, B, pref, umax_in, cst, has_prev, has_rate, dt, ws, iws, ubuf,
                           max_iter, tol, u_out, first, atol, rtol):
    """:func:`_allocate_step_trusted` and, on a converged step, what the output stage reads
    of it (``ActiveSetAllocator.allocate_tracked``): the achieved command ``B @ u``
    (``np.dot``, the BLAS ``dgemv`` that numpy's ``@`` calls: the same bits, checked in
    ``tests/test_inproc_fastpaths.py``), its :func:`shortfall_mask` against ``v`` and the
    command copied into ``u_out``. Returns ``(code, ok, iterations, mask, va[0])``;
    ``u_out`` is untouched and the mask 0 unless ``code >= 0 and ok``."""
    code, ok, it = _allocate_step_trusted(v, B, pref, umax_in, cst, has_prev, has_rate, dt, ws,
                                          iws, ubuf, max_iter, tol)
    if code < 0 or not ok:
        return code, ok, it, 0, 0.0
    va = np.dot(B, ubuf)
    u_out[:] = ubuf
    return code, ok, it, shortfall_mask(v, va, first, atol, rtol), va[0]


@numba.njit(cache=True)
def _allocate_step_tracked_packed(v, B, pref, umax_in, wsx, n_ws, has_prev, has_rate, dt, iws,
                                  max_iter, tol, u_out, first, atol, rtol, tail):
    """:func:`_allocate_step_tracked` with its ``ws``, ``cst`` and ``ubuf`` as consecutive
    parts of one array ``wsx`` (``ws`` its first ``n_ws`` entries, then ``cst`` (3, n_u),
    then ``ubuf`` (n_u); ``ActiveSetAllocator._pack``): 7 array arguments instead of 9, the
    same kernel on views of the same numbers; ``tail`` is first copied into the last entries
    of ``v`` (the output stage's moment demand; empty: ``v`` as given)."""
    nt = tail.size
    for i in range(nt):
        v[v.size - nt + i] = tail[i]
    n_u = B.shape[1]
    ws = wsx[0:n_ws]
    cst = wsx[n_ws:n_ws + 3 * n_u].reshape((3, n_u))
    ubuf = wsx[n_ws + 3 * n_u:n_ws + 4 * n_u]
    return _allocate_step_tracked(v, B, pref, umax_in, cst, has_prev, has_rate, dt, ws, iws,
                                  ubuf, max_iter, tol, u_out, first, atol, rtol)


@numba.njit(cache=True)
def _ppid_allocate_step_tracked(tab, vs, ref, att, rates, pws, sat_mask, v, B, pref, umax_in,
                                wsx, n_ws, has_prev, has_rate, dt, iws, max_iter, tol, u_out,
                                first, atol, rtol):
    """The attitude stage's scheduled P-PID step and the output stage's allocation of its
    moments in one compiled call: :func:`.control_kernels.scheduled_ppid3_step_packed` (``tab``
    to ``sat_mask``, its arguments), then :func:`_allocate_step_tracked_packed` (``v`` to
    ``rtol``) with the P-PID's output (``pws[W_OUT:W_SIZE]``, the moments [N m]) as ``tail``:
    the two kernels of ``AttitudeStage.update`` and ``allocate_tracked(..., v_tail=tau)``, in
    that order, on the same arrays (one dispatch and its argument checks fewer per step)."""
    scheduled_ppid3_step_packed(tab, vs, ref, att, rates, pws, sat_mask)
    return _allocate_step_tracked_packed(v, B, pref, umax_in, wsx, n_ws, has_prev, has_rate,
                                         dt, iws, max_iter, tol, u_out, first, atol, rtol,
                                         pws[W_OUT:W_SIZE])


def box_qp(
    H: np.ndarray,
    q: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    u0: np.ndarray,
    max_iter: int = 60,
    tol: float = 1e-15,
) -> tuple[np.ndarray, bool, int]:
    """Solve ``min 1/2 u'Hu + q'u  s.t.  lo <= u <= hi`` by the active-set method from ``u0``.

    Parameters
    ----------
    H : numpy.ndarray
        Symmetric positive definite Hessian (n x n).
    q : numpy.ndarray
        Linear term (n,).
    lo, hi : numpy.ndarray
        Bounds (n,), ``lo <= hi``.
    u0 : numpy.ndarray
        Starting point (n,), finite; clipped into the bounds, its active bounds (within 1e-6)
        form the initial working set.
    max_iter : int
        Maximum Newton steps / working-set changes.
    tol : float
        Relative KKT tolerance (see the module docstring for what it means).

    Returns
    -------
    tuple
        ``(u, ok, iterations)``; ``u`` is within the bounds; ``ok`` is True when the KKT test
        passed.
    """
    u, ok, it = box_qp_active_set(H, q, lo, hi, u0, max_iter, tol)
    return u, bool(ok), int(it)  # u stays within [lo, hi] by construction


def _readonly_c(a: np.ndarray) -> np.ndarray:
    """A read-only, C-contiguous view (or copy) of ``a``: the compiled kernels then see one
    array type whether the caller's matrix is a cached read-only one or its own writable one
    (each type would be compiled separately, a stall of seconds on a fresh install)."""
    out = np.ascontiguousarray(a).view()
    out.setflags(write=False)
    return out


class ActiveSetAllocator(WLSAllocator):
    """Weighted least-squares control allocation solved by the active-set ``box_qp`` alone.

    Every step starts ``box_qp`` from the previous command (before the first step, or after
    ``reset()``, from ``u_pref``), clipped into this step's bounds. Status ``SOLVED`` (and
    ``polished``) when its KKT test passes; otherwise ``FALLBACK`` (``wls``). No OSQP.

    Parameters
    ----------
    n_v, u_min, u_max, **options
        The problem, see ``wls.WLSAllocator`` (options: ``wls.ProblemOptions``).
    tol : float
        Relative KKT tolerance of ``box_qp`` (default 1e-15; 1e-9, the polish's, leaves the
        split among redundant actuators undetermined, see the module docstring).
    max_iter : int
        Maximum working-set changes per step (default 60).
    """

    def __init__(self, n_v: int, u_min: np.ndarray, u_max: np.ndarray, *,
                 tol: float = 1e-15, max_iter: int = 60,
                 **options: Unpack[ProblemOptions]) -> None:
        super().__init__(n_v, u_min, u_max, **options)
        if not (tol > 0 and np.isfinite(tol)):
            raise ValueError(f"tol must be finite and > 0, got {tol}")
        if max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {max_iter}")
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self._bk_of: np.ndarray | None = None  # the last C-contiguous B and its kernel view
        self._bk: np.ndarray | None = None
        self._pack()

    def _pack(self) -> None:
        """Move the QP's own arrays (``WLSAllocator``'s, same names, same values) into one
        float64 workspace and one int64 array, each attribute becoming a view of its part,
        in the order :func:`_allocate_step_packed` reads them; ``_lo``/``_hi``: the step's
        bounds."""
        n_u = self.n_u
        self._lo, self._hi = np.empty(n_u), np.empty(n_u)
        parts = [self._lo, self._hi, self._B_last, self._w_v2, self._reg, self._Hn,
                 self._Px, self._BtW2s, self._scale, self._qn]
        if self._tri_r.size != n_u * (n_u + 1) // 2:  # the layout the kernel assumes
            raise AssertionError("upper triangle of unexpected size")
        self._ws = np.concatenate([np.ravel(a) for a in parts]).astype(F64)
        self._iws = np.concatenate([self._tri_r, self._tri_c]).astype(np.int64)
        # allocate_trusted's kernel arguments: the limits as rows of one array (``u_min``,
        # ``u_max`` and ``rate_limit`` become views of it) and the command buffer
        rate = self.rate_limit
        cst = np.stack([self.u_min, self.u_max,
                        self._zeros_u if rate is None else rate]).astype(F64)
        # ``_ws``, ``_cst`` and ``_ubuf`` are in turn views of one array ``_wsx`` (the
        # tracked kernel's single float workspace: two array arguments fewer per call)
        self._n_ws = self._ws.size
        self._wsx = np.concatenate([self._ws, cst.ravel(), np.zeros(n_u)])
        self._link_views()

    _WS_PARTS = ("_lo", "_hi", "_B_last", "_w_v2", "_reg", "_Hn", "_Px", "_BtW2s", "_scale",
                 "_qn")
    """The attributes that are views of ``_ws``, in the kernel's order."""

    def _link_views(self) -> None:
        """Make the ``_WS_PARTS`` attributes views of ``_ws`` (each keeps its shape), the
        upper-triangle indices views of ``_iws`` and the limits views of ``_cst``; first
        ``_ws``, ``_cst`` (3, n_u) and ``_ubuf`` (n_u) as consecutive views of ``_wsx``."""
        n_ws, n_u = self._n_ws, self.n_u
        wsx = self._wsx
        self._ws = wsx[:n_ws]
        self._cst = wsx[n_ws:n_ws + 3 * n_u].reshape(3, n_u)
        self._ubuf = wsx[n_ws + 3 * n_u:]
        o = 0
        for name in self._WS_PARTS:
            a = getattr(self, name)
            setattr(self, name, self._ws[o:o + a.size].reshape(a.shape))
            o += a.size
        n_t = self._tri_r.size
        self._tri_r, self._tri_c = self._iws[:n_t], self._iws[n_t:]
        self.u_min, self.u_max = self._cst[0], self._cst[1]
        if self.rate_limit is not None:
            self.rate_limit = self._cst[2]

    def __setstate__(self, state: dict[str, object]) -> None:
        """A copy or unpickled allocator (``copy.deepcopy``, ``pickle``): numpy copies every
        array on its own, so the views of the workspace are linked again (else the copy's
        ``_lo``/``_hi`` and limits would no longer be what its kernel writes and reads)."""
        self.__dict__.update(state)
        self._link_views()

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
        """Allocate one step: ``WLSAllocator.allocate`` (same arguments, checks and results,
        bit for bit) with the bounds, the QP update and the solve in one compiled call
        (:func:`_allocate_step`). ``solve_time_s`` is that call's time."""
        t0 = _perf_counter()
        n_u = self.n_u
        if type(v) is not np.ndarray or v.dtype != F64:
            v = np.asarray(v, dtype=float)
        if type(B) is not np.ndarray or B.dtype != F64:
            B = np.asarray(B, dtype=float)
        if v.shape != (self.n_v,):
            raise ValueError(f"v: expected shape ({self.n_v},), got {v.shape}")
        if B.shape != (self.n_v, n_u):
            raise ValueError(f"B: expected shape ({self.n_v}, {n_u}), got {B.shape}")
        # one argument type for the kernel (warmup.py compiles it); B itself stays for B @ u.
        # The read-only view of a C-contiguous B shares its memory: kept while B is the same
        # object (the output stage passes the same few matrices step after step)
        Bk = self._bk if B is self._bk_of else self._kernel_matrix(B)
        if not v.flags.c_contiguous:
            v = np.ascontiguousarray(v)
        umin_in = self.u_min if u_min is None else vec_arg(u_min, n_u, "u_min")
        umax_in = self.u_max if u_max is None else vec_arg(u_max, n_u, "u_max")
        last = self._u_last
        prev = last if u_prev is None else vec_arg(u_prev, n_u, "u_prev")
        pref = self.u_pref if u_pref is None else vec_arg(u_pref, n_u, "u_pref")
        rate = self.rate_limit
        lo = self._lo  # views of the workspace, written by the kernel (this step's bounds)
        hi = self._hi
        u0 = last if last is not None else pref
        u = np.empty(n_u)
        t1 = _perf_counter()
        code, ok, it = _allocate_step_packed(
            v, Bk, pref, self.u_min, self.u_max, umin_in, umax_in,
            self._zeros_u if prev is None else prev, prev is not None,
            self._zeros_u if rate is None else rate, rate is not None, self.dt, self._ws,
            self._iws, u0, self.max_iter, self.tol, u)
        t_solve = _perf_counter() - t1
        if code < 0:
            hold = last if last is not None else self.u_pref
            return self._finish(np.clip(hold, lo, hi), v, B, ST_INVALID_INPUT, 0, 0.0, t0,
                                "non-finite input", False)
        if ok:
            return self._solved(u, v, B, it, t_solve, t0)
        u = self._fallback(v, B, lo, hi, pref, u)
        return self._finish(u, v, B, ST_FALLBACK, it, t_solve, t0, "active set not converged",
                            False)

    def allocate_trusted(self, v: np.ndarray, B: np.ndarray, u_max: np.ndarray,
                         u_pref: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """:meth:`allocate` for a caller whose arguments are already of the kernel's types:
        no argument checks and, on a converged step, no :class:`AllocationResult` (the
        output stage calls :meth:`allocate_tracked`: this and what it reads of ``B u`` in
        one compiled call).

        Parameters
        ----------
        v : numpy.ndarray
            Virtual command (n_v,) [N, N m], float64, C-contiguous.
        B : numpy.ndarray
            Effectiveness (n_v, n_u) [N or N m per normalised unit], float64, C-contiguous.
        u_max, u_pref : numpy.ndarray
            This step's upper position limits and preferred command (n_u,), float64,
            C-contiguous (lower limits: the construction ones).

        Returns
        -------
        tuple
            ``(u, v_achieved, status)``: the ``u``, ``v_achieved`` and ``status`` (an
            ``AllocationStatus`` value) that ``allocate(v, B, u_max=u_max, u_pref=u_pref)``
            returns, bit for bit: the same compiled kernels on the same numbers
            (:func:`_allocate_step_trusted`), the same ``B @ u`` in numpy, the same
            statistics (the non-converged branches are :meth:`allocate`'s own code). On a
            converged step ``u`` is the allocator's own buffer, overwritten by the next call:
            copy it, do not keep it.
        """
        t0 = _perf_counter()
        Bk = self._bk if B is self._bk_of else self._kernel_matrix(B)
        last = self._u_last
        u = self._ubuf
        if last is not None and last is not u:  # after reset(u0) or allocate(): its array
            u[:] = last
        code, ok, it = _allocate_step_trusted(
            v, Bk, u_pref, u_max, self._cst, last is not None, self.rate_limit is not None,
            self.dt, self._ws, self._iws, u, self.max_iter, self.tol)
        if code < 0 or not ok:
            return self._unconverged(code, it, v, B, u_pref, last, t0)
        # _solved's bookkeeping, without the result object
        va = B @ u
        self._u_last = u
        self._count_solved(it, t0)
        return u, va, ST_SOLVED

    def allocate_tracked(self, v: np.ndarray, B: np.ndarray, u_max: np.ndarray,
                         u_pref: np.ndarray, u_out: np.ndarray, first: int, atol: float,
                         rtol: float, *, v_tail: np.ndarray = _NO_TAIL,
                         ppid: tuple[Any, ...] | None = None) -> tuple[int, int, float]:
        """:meth:`allocate_trusted` with the command written into ``u_out`` and, instead of
        ``B u``, what the output stage reads of it: one compiled call
        (:func:`_allocate_step_tracked`) on a converged step.

        Parameters
        ----------
        v, B, u_max, u_pref
            As :meth:`allocate_trusted` (the kernel's types, no checks).
        u_out : numpy.ndarray
            (n_u,) float64: receives the command ``u`` (normalised units).
        first, atol, rtol
            :func:`~.interface.shortfall_mask`'s, applied to ``v`` and ``B u``.
        v_tail : numpy.ndarray, optional
            (k,) float64, copied into ``v[-k:]`` before anything reads ``v`` (the output
            stage's moment demand, written by the same compiled call).
        ppid : tuple, optional
            ``(tab, vs, ref, att, rates, ws, sat_mask)``, the arguments of
            :func:`.control_kernels.scheduled_ppid3_step_packed` (the attitude stage's
            ``kernel_step_args``): that step first, its moments as ``v_tail``, in the same
            compiled call (:func:`_ppid_allocate_step_tracked`).

        Returns
        -------
        tuple
            ``(status, mask, fz_achieved)``: ``allocate_trusted``'s status, the shortfall
            mask of ``v`` against its ``B u`` and ``(B u)[0]`` [N]; ``u_out`` and the
            allocator's state exactly as after ``allocate_trusted`` (the same kernels, the
            same ``dgemv``: the same bits).
        """
        t0 = _perf_counter()
        Bk = self._bk if B is self._bk_of else self._kernel_matrix(B)
        last = self._u_last
        u = self._ubuf
        if last is not None and last is not u:
            u[:] = last
        if ppid is None:
            code, ok, it, mask, fz = _allocate_step_tracked_packed(
                v, Bk, u_pref, u_max, self._wsx, self._n_ws, last is not None,
                self.rate_limit is not None, self.dt, self._iws, self.max_iter, self.tol,
                u_out, first, atol, rtol, v_tail)
        else:
            code, ok, it, mask, fz = _ppid_allocate_step_tracked(
                *ppid, v, Bk, u_pref, u_max, self._wsx, self._n_ws, last is not None,
                self.rate_limit is not None, self.dt, self._iws, self.max_iter, self.tol,
                u_out, first, atol, rtol)
        if code < 0 or not ok:
            u_res, va, status = self._unconverged(code, it, v, B, u_pref, last, t0)
            u_out[:] = u_res
            return status, shortfall_mask(v, va, first, atol, rtol), float(va[0])
        self._u_last = u
        self._count_solved(it, t0)
        return ST_SOLVED, mask, fz

    def _kernel_matrix(self, B: np.ndarray) -> np.ndarray:
        """``B`` as the kernels take it (read-only, C-contiguous), kept while ``B`` is the
        same C-contiguous object."""
        Bk = _readonly_c(B) if B.flags.writeable or not B.flags.c_contiguous else B
        if B.flags.c_contiguous:
            self._bk_of, self._bk = B, Bk
        return Bk

    def _unconverged(self, code: int, it: int, v: np.ndarray, B: np.ndarray,
                     u_pref: np.ndarray, last: np.ndarray | None,
                     t0: float) -> tuple[np.ndarray, np.ndarray, int]:
        """The trusted calls' answer when the kernel found a non-finite input (``code < 0``:
        the previous command held) or did not converge (the fallback)."""
        if code < 0:
            hold = last if last is not None else self.u_pref
            res = self._finish(np.clip(hold, self._lo, self._hi), v, B, ST_INVALID_INPUT, 0,
                               0.0, t0, "non-finite input", False)
            return res.u, res.v_achieved, ST_INVALID_INPUT
        u = self._fallback(v, B, self._lo, self._hi, u_pref, self._ubuf)
        res = self._finish(u, v, B, ST_FALLBACK, it, 0.0, t0, "active set not converged",
                           False)
        return res.u, res.v_achieved, ST_FALLBACK

    def _count_solved(self, it: int, t0: float) -> None:
        """The statistics of a converged trusted step (``_solved``'s, no result object)."""
        st = self.stats
        st.calls += 1
        st.counts[ST_SOLVED] += 1
        st.total_iterations += it
        if it > st.max_iterations:
            st.max_iterations = it
        t_wall = _perf_counter() - t0
        st.total_wall_time_s += t_wall
        if t_wall > st.max_wall_time_s:
            st.max_wall_time_s = t_wall

    def _solved(self, u: np.ndarray, v: np.ndarray, B: np.ndarray, it: int, t_solve: float,
                t0: float) -> AllocationResult:
        """``_finish(u, v, B, ST_SOLVED, it, t_solve, t0, "solved", True)`` with the
        bookkeeping written out (the hot path: a converged step)."""
        va = B @ u
        self._u_last = u
        res = new_result(u, va, va - v, ST_SOLVED, it, t_solve, _perf_counter() - t0,
                          "solved", True)
        st = self.stats
        st.calls += 1
        st.counts[ST_SOLVED] += 1
        st.total_iterations += it
        if it > st.max_iterations:
            st.max_iterations = it
        t_wall = res.wall_time_s
        st.total_wall_time_s += t_wall
        if t_wall > st.max_wall_time_s:
            st.max_wall_time_s = t_wall
        return res

    def _solve(self, v: np.ndarray, B: np.ndarray, pref: np.ndarray, lo: np.ndarray,
               hi: np.ndarray, B_changed: bool, t0: float) -> AllocationResult:
        u0 = self._u_last if self._u_last is not None else pref
        t1 = _perf_counter()
        u, ok, it = box_qp_active_set(self._Hn, self._qn, lo, hi, u0, self.max_iter, self.tol)
        t_solve = _perf_counter() - t1
        if ok:
            return self._solved(u, v, B, it, t_solve, t0)
        u = self._fallback(v, B, lo, hi, pref, u)
        return self._finish(u, v, B, ST_FALLBACK, it, t_solve, t0, "active set not converged",
                            False)
