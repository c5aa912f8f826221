"""The compiled attitude control laws: the one implementation of the cascaded P-PID step and
of the LQR law with integral action (paper fig. 5; :mod:`.pid`, :mod:`.lqr`).

Why compiled: the law runs for three axes at every 250 Hz control step of every flight, and
campaigns fly thousands of flights in-process; numba turns a Python step of a few tens of
microseconds into a fraction of one. It is the only copy of the law: the Python classes
(:class:`~vtolftc.firmware_sim.autopilot.pid.CascadedPPID`, the controllers in
:mod:`~vtolftc.firmware_sim.autopilot.attitude`) are views of the arrays these kernels update.
The kernels are written without ``fastmath``, so they give the same bits as the same
expressions in IEEE double precision (flights are reproducible bit for bit).

Array layout of a P-PID axis (one row per axis):

- gains ``g`` (5,): ``kp_angle`` [1/s], ``kp_rate`` [N m s/rad], ``ki_rate`` [N m/rad],
  ``kd_rate`` [N m s^2/rad], ``tf_rate_s`` [s] (columns ``G_*``);
- state ``S[k]`` (10,), columns ``S_*``: the integral of ``ki e`` [N m], the filtered
  ``kd de/dt`` [N m], the previous rate error [rad/s], the ``tf`` the cached filter
  coefficients belong to [s] (NaN: none yet), the filter pole and gain [1/s], the last rate
  reference [rad/s], output [N m], output before the limits [N m], saturated (1.0 / 0.0);
- constants ``C[k]`` (6,), columns ``C_*``: wrap the angle error (1.0 / 0.0), rate reference
  limit [rad/s] (NaN: none), sample time [s], Tustin (1.0) or backward Euler (0.0), lower and
  upper output limits [N m].

The discretisation and the anti-windup are described in :mod:`.pid`.
"""

from __future__ import annotations

import math

import numba

__all__ = [
    "C_DT", "C_RATE_LIMIT", "C_TUSTIN", "C_U_MAX", "C_U_MIN", "C_WRAP", "G_KD_RATE",
    "G_KI_RATE", "G_KP_ANGLE", "G_KP_RATE", "G_TF_RATE", "N_CONST", "N_GAINS", "N_STATE",
    "S_A", "S_B", "S_DERIVATIVE", "S_E_PREV", "S_INTEGRAL", "S_OUTPUT", "S_OUTPUT_UNSAT",
    "S_RATE_REF", "S_SATURATED", "S_TF", "W_CONST", "W_GAINS", "W_OUT", "W_SIZE", "W_STATE",
    "filter_coefficients", "lqr3_step", "ppid3_step", "ppid_rate_reference", "ppid_rate_step",
    "ppid_step", "scheduled_gains", "scheduled_ppid3_step", "scheduled_ppid3_step_packed",
    "wrap_angle",
]

#: columns of the P-PID gains row
G_KP_ANGLE, G_KP_RATE, G_KI_RATE, G_KD_RATE, G_TF_RATE = range(5)
N_GAINS = 5
#: columns of the P-PID state row
(S_INTEGRAL, S_DERIVATIVE, S_E_PREV, S_TF, S_A, S_B, S_RATE_REF, S_OUTPUT, S_OUTPUT_UNSAT,
 S_SATURATED) = range(10)
N_STATE = 10
#: columns of the P-PID constants row
C_WRAP, C_RATE_LIMIT, C_DT, C_TUSTIN, C_U_MIN, C_U_MAX = range(6)
N_CONST = 6

#: The packed workspace of a three-axis P-PID (:func:`scheduled_ppid3_step_packed`): the
#: gains (3, N_GAINS), state (3, N_STATE), constants (3, N_CONST) and output (3,), each
#: C-ordered, from these offsets; W_SIZE entries in all.
W_GAINS = 0
W_STATE = W_GAINS + 3 * N_GAINS
W_CONST = W_STATE + 3 * N_STATE
W_OUT = W_CONST + 3 * N_CONST
W_SIZE = W_OUT + 3

TWO_PI = 2.0 * math.pi


@numba.njit(cache=True)
def _max2(a: float, b: float) -> float:  # pragma: no cover - compiled
    return b if b > a else a  # builtins.max(a, b)


@numba.njit(cache=True)
def _min2(a: float, b: float) -> float:  # pragma: no cover - compiled
    return b if b < a else a  # builtins.min(a, b)


@numba.njit(cache=True)
def _pick3(k: int, x0: bool, x1: bool, x2: bool) -> bool:  # pragma: no cover - compiled
    """``(x0, x1, x2)[k]`` (per-axis flags come as scalars: no array per control step)."""
    if k == 0:
        return x0
    return x1 if k == 1 else x2


@numba.njit(cache=True)
def wrap_angle(x: float) -> float:  # pragma: no cover - compiled
    """Wrap an angle to (-pi, pi].

    Parameters
    ----------
    x : float
        Angle [rad].

    Returns
    -------
    float
        The same angle in (-pi, pi] [rad].
    """
    return -((-x + math.pi) % TWO_PI - math.pi)


@numba.njit(cache=True)
def filter_coefficients(tf: float, dt: float, tustin: bool) -> tuple[float, float]:
    """Coefficients of the discrete derivative filter ``d_k = a d_{k-1} + b kd (e_k - e_{k-1})``.

    Parameters
    ----------
    tf : float
        Filter time constant [s].
    dt : float
        Sample time [s].
    tustin : bool
        Tustin (used when ``tf >= dt/2``; below that its pole would be negative) or
        backward Euler.

    Returns
    -------
    a, b : float
        Pole (dimensionless, in [0, 1)) and gain [1/s]: Tustin ``(2tf - dt)/(2tf + dt)``,
        ``2/(2tf + dt)``; backward Euler ``tf/(tf + dt)``, ``1/(tf + dt)``.
    """
    if tustin and tf >= 0.5 * dt:
        return (2.0 * tf - dt) / (2.0 * tf + dt), 2.0 / (2.0 * tf + dt)
    return tf / (tf + dt), 1.0 / (tf + dt)


@numba.njit(cache=True)
def ppid_rate_reference(g, C, k, angle_ref, angle, rate_ff):  # pragma: no cover - compiled
    """Outer P loop of axis ``k``; reads no state.

    Parameters
    ----------
    g, C, k
        Gains (5,), constants (n, 6) and the axis row, as :func:`ppid_rate_step`.
    angle_ref, angle : float
        Reference and measured angle [rad] (error wrapped if ``C[k, C_WRAP]``).
    rate_ff : float
        Rate feed-forward [rad/s].

    Returns
    -------
    float
        ``kp_angle (angle_ref - angle) + rate_ff`` limited to the rate limit [rad/s].
    """
    err = angle_ref - angle
    if C[k, C_WRAP] != 0.0:
        err = wrap_angle(err)
    r = g[G_KP_ANGLE] * err + rate_ff
    lim = C[k, C_RATE_LIMIT]
    if lim == lim:
        r = _min2(_max2(r, -lim), lim)
    return r


@numba.njit(cache=True)
def ppid_rate_step(g, S, C, k, rate_ref, rate):  # pragma: no cover - compiled
    """Inner PID loop of axis ``k``: one step on ``e = rate_ref - rate``.

    Parameters
    ----------
    g : numpy.ndarray, shape (5,)
        Gains of the axis (``G_*`` columns).
    S : numpy.ndarray, shape (n, 10)
        State (``S_*`` columns); row ``k`` is read and written.
    C : numpy.ndarray, shape (n, 6)
        Constants (``C_*`` columns); row ``k`` is used.
    k : int
        Axis row.
    rate_ref, rate : float
        Rate reference and measured body rate of the axis [rad/s].

    Returns
    -------
    float
        Moment [N m] within the output limits.
    """
    e = rate_ref - rate
    e_prev = S[k, S_E_PREV]
    de = e - e_prev
    tf = g[G_TF_RATE]
    dt = C[k, C_DT]
    tustin = C[k, C_TUSTIN] != 0.0
    if tf == S[k, S_TF]:
        a = S[k, S_A]
        b = S[k, S_B]
    else:
        a, b = filter_coefficients(tf, dt, tustin)
        S[k, S_TF] = tf
        S[k, S_A] = a
        S[k, S_B] = b
    derivative = a * S[k, S_DERIVATIVE] + b * g[G_KD_RATE] * de
    S[k, S_DERIVATIVE] = derivative
    dI = 0.5 * g[G_KI_RATE] * dt * (e + e_prev) if tustin else g[G_KI_RATE] * dt * e
    p = g[G_KP_RATE] * e
    integral = S[k, S_INTEGRAL]
    u_min = C[k, C_U_MIN]
    u_max = C[k, C_U_MAX]
    u_test = p + integral + dI + derivative
    # conditional integration: integrate at most up to the limit, never further into it
    if dI > 0.0 and u_test > u_max:
        dI = _max2(0.0, u_max - (u_test - dI))
    elif dI < 0.0 and u_test < u_min:
        dI = _min2(0.0, u_min - (u_test - dI))
    integral = _min2(_max2(integral + dI, u_min), u_max)
    S[k, S_INTEGRAL] = integral
    o = p + integral + derivative
    S[k, S_OUTPUT_UNSAT] = o
    S[k, S_SATURATED] = 1.0 if (o >= u_max or o <= u_min) else 0.0
    o = _min2(_max2(o, u_min), u_max)
    S[k, S_E_PREV] = e
    S[k, S_RATE_REF] = rate_ref
    S[k, S_OUTPUT] = o
    return o


@numba.njit(cache=True)
def ppid_step(g, S, C, k, angle_ref, angle, rate, rate_ff, sat_hi,
              sat_lo):  # pragma: no cover - compiled
    """One cascaded P-PID step of axis ``k`` (outer P loop, inner PID loop).

    Parameters
    ----------
    g, S, C, k
        Gains (5,), state (n, 10), constants (n, 6) and the axis row, as
        :func:`ppid_rate_step`.
    angle_ref, angle : float
        Reference and measured angle [rad].
    rate : float
        Measured body rate of the axis [rad/s].
    rate_ff : float
        Rate feed-forward [rad/s].
    sat_hi, sat_lo : bool
        The allocation saturated this axis upwards / downwards last step: the integral does
        not grow / shrink this step, and its increment is taken back out of the output.

    Returns
    -------
    float
        Moment [N m].
    """
    before = S[k, S_INTEGRAL]
    r = ppid_rate_reference(g, C, k, angle_ref, angle, rate_ff)
    o = ppid_rate_step(g, S, C, k, r, rate)
    di = S[k, S_INTEGRAL] - before
    if (di > 0.0 and sat_hi) or (di < 0.0 and sat_lo):
        o -= di
        S[k, S_INTEGRAL] = before
    return o


@numba.njit(cache=True)
def ppid3_step(ref, att, rates, G, S, C, sat_hi0, sat_hi1, sat_hi2, sat_lo0, sat_lo1,
               sat_lo2, out):  # pragma: no cover - compiled
    """:func:`ppid_step` for the three axes (roll, pitch, yaw) in one call, no feed-forward.

    Parameters
    ----------
    ref, att : numpy.ndarray, shape (3,)
        Reference and measured ZYX Euler angles [rad].
    rates : numpy.ndarray, shape (3,)
        Body rates p, q, r, FRD [rad/s].
    G, S, C : numpy.ndarray
        Gains (3, 5), state (3, 10; read and written), constants (3, 6).
    sat_hi0, sat_hi1, sat_hi2, sat_lo0, sat_lo1, sat_lo2 : bool
        The allocation's saturation flags per axis (see :func:`ppid_step`).
    out : numpy.ndarray, shape (3,)
        Receives the moments [N m], FRD body axes.
    """
    for k in range(3):
        sh = _pick3(k, sat_hi0, sat_hi1, sat_hi2)
        sl = _pick3(k, sat_lo0, sat_lo1, sat_lo2)
        out[k] = ppid_step(G[k], S, C, k, ref[k], att[k], rates[k], 0.0, sh, sl)


@numba.njit(cache=True)
def lqr3_step(ref, att, rates, K, dt, it, sat_hi0, sat_hi1, sat_hi2, sat_lo0, sat_lo1,
              sat_lo2, out):  # pragma: no cover - compiled
    """LQR law with integral action for the three axes:
    ``tau = k_int int(e) + k_angle e - k_rate rate`` (yaw error wrapped).

    Parameters
    ----------
    ref, att, rates
        Angles [rad] and body rates [rad/s], as :func:`ppid3_step`.
    K : numpy.ndarray, shape (3, 3)
        Per axis ``k_int`` [N m/(rad s)], ``k_angle`` [N m/rad], ``k_rate`` [N m s/rad].
    dt : float
        Sample time [s].
    it : numpy.ndarray, shape (3,)
        The integral terms ``k_int int(e)`` [N m], read and written (kept in output units so
        that scheduled gains are bumpless); not moved towards a saturated side.
    sat_hi0, sat_hi1, sat_hi2, sat_lo0, sat_lo1, sat_lo2, out
        Saturation flags per axis and the output (3,) [N m], as :func:`ppid3_step`.
    """
    for k in range(3):
        sh = _pick3(k, sat_hi0, sat_hi1, sat_hi2)
        sl = _pick3(k, sat_lo0, sat_lo1, sat_lo2)
        e = ref[k] - att[k]
        if k == 2:
            e = wrap_angle(e)
        dI = K[k, 0] * e * dt
        if not ((dI > 0.0 and sh) or (dI < 0.0 and sl)):
            it[k] += dI
        out[k] = K[k, 1] * e - K[k, 2] * rates[k] + it[k]


@numba.njit(cache=True)
def scheduled_gains(bp, rows, slopes, V, out):  # pragma: no cover - compiled
    """Gains of a schedule at airspeed ``V`` [m/s], piecewise-linear between breakpoints and
    clamped outside: ``GainSchedule.gains_at`` (same arithmetic, same bits) as the kernel's
    array.

    Parameters
    ----------
    bp : numpy.ndarray, shape (n,)
        Breakpoint airspeeds [m/s], increasing.
    rows : numpy.ndarray, shape (n, 3, 5)
        The gains at each breakpoint (axis, ``G_*`` column).
    slopes : numpy.ndarray, shape (max(n - 1, 1), 3, 5)
        ``rows[i + 1] - rows[i]`` per interval.
    V : float
        Airspeed [m/s]; NaN gives the first breakpoint's gains, as below the first.
    out : numpy.ndarray, shape (3, 5)
        Receives the gains.
    """
    n = bp.shape[0]
    if not bp[0] < V:  # also NaN
        out[:, :] = rows[0]
        return
    if bp[n - 1] <= V:
        out[:, :] = rows[n - 1]
        return
    i = 0
    while bp[i + 1] <= V:  # bisect_right(bp, V) - 1
        i += 1
    w = (V - bp[i]) / (bp[i + 1] - bp[i])
    if w == 0.0:
        out[:, :] = rows[i]
        return
    for a in range(3):
        for c in range(5):
            out[a, c] = rows[i, a, c] + w * slopes[i, a, c]


@numba.njit(cache=True)
def scheduled_ppid3_step(bp, rows, slopes, V, ref, att, rates, G, S, C, sat_hi0, sat_hi1,
                         sat_hi2, sat_lo0, sat_lo1, sat_lo2, out):  # pragma: no cover
    """:func:`scheduled_gains` at ``V`` into ``G``, then :func:`ppid3_step` with them: the
    scheduled controller's step in one call (parameters as those two functions')."""
    scheduled_gains(bp, rows, slopes, V, G)
    ppid3_step(ref, att, rates, G, S, C, sat_hi0, sat_hi1, sat_hi2, sat_lo0, sat_lo1,
               sat_lo2, out)


@numba.njit(cache=True)
def scheduled_ppid3_step_packed(tab, V, ref, att, rates, ws,
                                sat_mask):  # pragma: no cover - compiled
    """:func:`scheduled_ppid3_step` on two packed arrays instead of seven and one int instead
    of six bools (each argument of a compiled call costs its own type check and unboxing):
    the same kernels on views of them, with the same flags.

    Parameters
    ----------
    tab : numpy.ndarray, shape (16 n + 15 max(n - 1, 1),)
        The schedule's breakpoints (n,), rows (n, 3, 5) and slopes (max(n - 1, 1), 3, 5),
        concatenated (``GainSchedule.kernel_packed``): n = 1 for 31 entries, else
        (size + 15) / 31.
    V, ref, att, rates
        As :func:`scheduled_ppid3_step`.
    ws : numpy.ndarray, shape (W_SIZE,)
        Gains, state, constants and output at the ``W_*`` offsets (read and written as
        :func:`scheduled_ppid3_step` does its ``G``, ``S``, ``C``, ``out``).
    sat_mask : int
        The saturation flags as the output stage's shortfall mask: bits 0-2 ``sat_hi0`` to
        ``sat_hi2``, bits 3-5 ``sat_lo0`` to ``sat_lo2``.
    """
    size = tab.shape[0]
    n = 1 if size == 31 else (size + 15) // 31
    m = n - 1 if n > 1 else 1
    bp = tab[0:n]
    rows = tab[n:16 * n].reshape((n, 3, 5))
    slopes = tab[16 * n:16 * n + 15 * m].reshape((m, 3, 5))
    G = ws[W_GAINS:W_STATE].reshape((3, N_GAINS))
    S = ws[W_STATE:W_CONST].reshape((3, N_STATE))
    C = ws[W_CONST:W_OUT].reshape((3, N_CONST))
    out = ws[W_OUT:W_SIZE]
    scheduled_ppid3_step(bp, rows, slopes, V, ref, att, rates, G, S, C, (sat_mask & 1) != 0,
                         (sat_mask & 2) != 0, (sat_mask & 4) != 0, (sat_mask & 8) != 0,
                         (sat_mask & 16) != 0, (sat_mask & 32) != 0, out)
