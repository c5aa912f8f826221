"""Attitude controllers behind one interface, selectable by name.

- ``gs-shif``: the paper's gain-scheduled cascaded P-PID per axis (``gains/gs-shif.json``,
  a :class:`~vtolftc.firmware_sim.autopilot.schedule.GainSchedule`), gains interpolated in the
  measured airspeed every step;
- ``shif``: the same class with the constant-gain schedule ``gains/shif.json``;
- ``lqr``: state feedback with integral action per axis (``gains/lqr.json``, see
  :mod:`vtolftc.firmware_sim.autopilot.lqr`).

All take the attitude reference and the measured attitude (roll, pitch, yaw; ZYX Euler, rad),
the body rates (rad/s) and the airspeed (m/s), and return the moment command [L, M, N] (N m,
FRD body axes). The yaw error is wrapped to (-pi, pi]. Anti-windup by feedback of the
allocation's saturation: the caller passes, per axis, whether the last allocation fell short
of the commanded moment upwards (``sat_hi``) or downwards (``sat_lo``); the integrator of
that axis then does not move further in that direction (conditional integration; the output
itself is not clipped, since the weighted allocation achieves part of any larger command).
The controllers never see fault state: only navigation data (passive FTC).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

import numba
import numpy as np
from numpy.typing import NDArray

from vtolftc.firmware_sim.autopilot.lqr import LQRAxisGains, LQRGains, LQRGainsError
from vtolftc.firmware_sim.autopilot.pid import TWO_PI, CascadedPPID, PPIDGains, wrap_angle
from vtolftc.firmware_sim.autopilot.schedule import AXES, GainSchedule, GainScheduleError

__all__ = [
    "CONTROLLERS",
    "AttitudeController",
    "ControllerError",
    "LQRAttitudeController",
    "ScheduledPPIDController",
    "default_gains_dir",
    "gains_file",
    "make_controller",
]

#: Controller names and their gain files.
CONTROLLERS: dict[str, str] = {"gs-shif": "gs-shif.json", "shif": "shif.json",
                               "lqr": "lqr.json"}


class ControllerError(ValueError):
    """Unknown controller name, missing or invalid gain file (the message says what to do)."""


def default_gains_dir() -> Path:
    """The shipped gains directory, ``firmware_sim/autopilot/gains``."""
    return Path(__file__).with_name("gains")


def gains_file(controller: str, gains_dir: str | Path | None = None) -> Path:
    """Path of the gain file of ``controller`` in ``gains_dir`` (default: the shipped one)."""
    if controller not in CONTROLLERS:
        raise ControllerError(f"unknown controller {controller!r}: expected one of "
                              f"{', '.join(CONTROLLERS)}")
    d = Path(gains_dir) if gains_dir is not None else default_gains_dir()
    return d / CONTROLLERS[controller]


class AttitudeController(Protocol):
    """What the autopilot needs from an attitude controller."""

    name: str
    gains_path: Path
    gains_sha256: str

    def reset(self) -> None:
        """Clear the integrators (on arming, and every step while still on the ground)."""

    def update(self, ref: NDArray[np.float64], att: NDArray[np.float64],
               rates: NDArray[np.float64], airspeed_m_s: float,
               sat_hi: Sequence[bool], sat_lo: Sequence[bool]) -> NDArray[np.float64]:
        """Moment demand for one control step.

        Parameters
        ----------
        ref, att : numpy.ndarray
            attitude reference and measured attitude, (roll, pitch, yaw) ZYX Euler angles (rad).
        rates : numpy.ndarray
            body rates p, q, r, FRD (rad/s).
        airspeed_m_s : float
            airspeed (m/s), the scheduling variable.
        sat_hi, sat_lo : sequence of bool
            per axis, the allocator saturated the moment at its upper / lower limit last step
            (anti-windup: the integrators do not move further that way).

        Returns
        -------
        numpy.ndarray
            moment demand (roll, pitch, yaw) about the body FRD axes (N m).
        """


def _floats3(x: NDArray[np.float64] | tuple[float, ...] | list[float]) -> list[float]:
    """The first three entries of ``x`` as Python floats (fast for float ndarrays)."""
    if type(x) is np.ndarray and x.shape == (3,):
        return x.tolist()
    return [float(x[0]), float(x[1]), float(x[2])]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# columns of the P-PID axes' state array (one row per axis), see _ArrayPPID
_S_INTEGRAL, _S_DERIV, _S_EPREV, _S_TF, _S_A, _S_B, _S_RREF, _S_OUT, _S_UNSAT, _S_SAT = range(10)
# columns of the constants array: wrap, rate limit (NaN = none), dt, tustin, u_min, u_max
_N_STATE, _N_CONST = 10, 6
_F64 = np.dtype(np.float64)


@numba.njit(cache=True)
def _max2(a: float, b: float) -> float:
    return b if b > a else a  # builtins.max(a, b)


@numba.njit(cache=True)
def _min2(a: float, b: float) -> float:
    return b if b < a else a  # builtins.min(a, b)


@numba.njit(cache=True)
def _ppid3_step(ref, att, rates, G, S, C, sat_hi0, sat_hi1, sat_hi2, sat_lo0, sat_lo1,
                sat_lo2, out):  # pragma: no cover - compiled
    """The three axes of :meth:`ScheduledPPIDController.update` in one compiled call: the
    same expressions in the same order as ``CascadedPPID.update`` plus the anti-windup
    (so the same bits). ``G`` (3, 5): kp_angle, kp_rate, ki_rate, kd_rate, tf_rate_s per axis;
    ``S`` (3, 10) the axes' state (read and written), ``C`` (3, 6) their constants; ``out``
    (3,) receives the moments [N m]."""
    two_pi = 2.0 * math.pi
    for k in range(3):
        if k == 0:
            sh, sl = sat_hi0, sat_lo0
        elif k == 1:
            sh, sl = sat_hi1, sat_lo1
        else:
            sh, sl = sat_hi2, sat_lo2
        before = S[k, 0]
        err = ref[k] - att[k]
        if C[k, 0] != 0.0:
            err = -((-err + math.pi) % two_pi - math.pi)  # wrap_angle
        r = G[k, 0] * err + 0.0  # + rate_ff
        lim = C[k, 1]
        if lim == lim:
            r = _min2(_max2(r, -lim), lim)
        e = r - rates[k]
        e_prev = S[k, 2]
        de = e - e_prev
        tf = G[k, 4]
        dt = C[k, 2]
        tustin = C[k, 3] != 0.0
        if tf == S[k, 3]:
            a = S[k, 4]
            b = S[k, 5]
        else:  # CascadedPPID._filter_coeffs
            if tustin and tf >= 0.5 * dt:
                a = (2.0 * tf - dt) / (2.0 * tf + dt)
                b = 2.0 / (2.0 * tf + dt)
            else:
                a = tf / (tf + dt)
                b = 1.0 / (tf + dt)
            S[k, 3] = tf
            S[k, 4] = a
            S[k, 5] = b
        derivative = a * S[k, 1] + b * G[k, 3] * de
        S[k, 1] = derivative
        dI = 0.5 * G[k, 2] * dt * (e + e_prev) if tustin else G[k, 2] * dt * e
        p = G[k, 1] * e
        integral = before
        u_min = C[k, 4]
        u_max = C[k, 5]
        u_test = p + integral + dI + derivative
        if dI > 0.0 and u_test > u_max:
            dI = _max2(0.0, u_max - (u_test - dI))
        elif dI < 0.0 and u_test < u_min:
            dI = _min2(0.0, u_min - (u_test - dI))
        integral = _min2(_max2(integral + dI, u_min), u_max)
        S[k, 0] = integral
        o = p + integral + derivative
        S[k, 8] = o
        S[k, 9] = 1.0 if (o >= u_max or o <= u_min) else 0.0
        o = _min2(_max2(o, u_min), u_max)
        S[k, 2] = e
        S[k, 6] = r
        S[k, 7] = o
        di = integral - before
        if (di > 0.0 and sh) or (di < 0.0 and sl):
            o -= di
            S[k, 0] = before
        out[k] = o


@numba.njit(cache=True)
def _lqr3_step(ref, att, rates, K, dt, it, sat_hi0, sat_hi1, sat_hi2, sat_lo0, sat_lo1,
               sat_lo2, out):  # pragma: no cover - compiled
    """The three axes of :meth:`LQRAttitudeController.update` in one compiled call (same
    expressions, same order, same bits). ``K`` (3, 3): k_int, k_angle, k_rate per axis;
    ``it`` (3,) the integral terms (read and written); ``out`` (3,) the moments [N m]."""
    two_pi = 2.0 * math.pi
    for k in range(3):
        if k == 0:
            sh, sl = sat_hi0, sat_lo0
        elif k == 1:
            sh, sl = sat_hi1, sat_lo1
        else:
            sh, sl = sat_hi2, sat_lo2
        e = ref[k] - att[k]
        if k == 2:
            e = -((-e + math.pi) % two_pi - math.pi)  # wrap_angle
        dI = K[k, 0] * e * dt
        if not ((dI > 0.0 and sh) or (dI < 0.0 and sl)):
            it[k] += dI
        out[k] = K[k, 1] * e - K[k, 2] * rates[k] + it[k]


def _row_property(col: int, doc: str, as_bool: bool = False) -> property:
    def get(self: _ArrayPPID) -> float | bool:
        v = float(self._state[self._k, col])
        return v != 0.0 if as_bool else v

    def put(self: _ArrayPPID, value: float) -> None:
        self._state[self._k, col] = float(value)

    return property(get, put, doc=doc)


class _ArrayPPID(CascadedPPID):
    """A :class:`CascadedPPID` whose state lives in row ``k`` of ``state`` (the controller's
    ``(3, 10)`` state array): the same attributes, read and written as before, and the
    array the compiled three-axis step works on. The whole array and the row index are
    kept (not a view), so a deep copy or pickle of the controller keeps them shared."""

    def __init__(self, state: NDArray[np.float64], const: NDArray[np.float64], k: int,
                 *args: object, **kwargs: object) -> None:
        self._state = state
        self._const = const
        self._k = k
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    # the constants too (CascadedPPID's public attributes), so changing one acts on the
    # compiled step as it does on CascadedPPID.update
    @property
    def wrap(self) -> bool:  # type: ignore[override]
        """Wrap the angle error to (-pi, pi] (yaw)."""
        return bool(self._const[self._k, 0] != 0.0)

    @wrap.setter
    def wrap(self, value: bool) -> None:
        self._const[self._k, 0] = 1.0 if value else 0.0

    @property
    def rate_limit(self) -> float | None:  # type: ignore[override]
        """Limit of the rate reference [rad/s], None for none."""
        v = float(self._const[self._k, 1])
        return None if v != v else v

    @rate_limit.setter
    def rate_limit(self, value: float | None) -> None:
        self._const[self._k, 1] = math.nan if value is None else float(value)

    @property
    def dt(self) -> float:  # type: ignore[override]
        """Control period [s]."""
        return float(self._const[self._k, 2])

    @dt.setter
    def dt(self, value: float) -> None:
        self._const[self._k, 2] = float(value)

    @property
    def method(self) -> str:  # type: ignore[override]
        """Integration method, ``tustin`` or ``backward_euler``."""
        return "tustin" if self._const[self._k, 3] != 0.0 else "backward_euler"

    @method.setter
    def method(self, value: str) -> None:
        if value not in ("tustin", "backward_euler"):
            raise ValueError(f"method must be 'tustin' or 'backward_euler', got {value!r}")
        self._const[self._k, 3] = 1.0 if value == "tustin" else 0.0

    @property
    def u_min(self) -> float:  # type: ignore[override]
        """Lower output limit [N m]."""
        return float(self._const[self._k, 4])

    @u_min.setter
    def u_min(self, value: float) -> None:
        self._const[self._k, 4] = float(value)

    @property
    def u_max(self) -> float:  # type: ignore[override]
        """Upper output limit [N m]."""
        return float(self._const[self._k, 5])

    @u_max.setter
    def u_max(self, value: float) -> None:
        self._const[self._k, 5] = float(value)

    integral = _row_property(_S_INTEGRAL, "integral of ki e dt [N m]")
    derivative = _row_property(_S_DERIV, "filtered kd de/dt [N m]")
    _e_prev = _row_property(_S_EPREV, "previous rate error [rad/s]")
    _tf_cached = _row_property(_S_TF, "tf of the cached filter coefficients [s]")
    _a = _row_property(_S_A, "derivative filter pole")
    _b = _row_property(_S_B, "derivative filter gain [1/s]")
    rate_ref = _row_property(_S_RREF, "last rate reference [rad/s]")
    output = _row_property(_S_OUT, "last output [N m]")
    output_unsat = _row_property(_S_UNSAT, "last output before the limits [N m]")
    saturated = _row_property(_S_SAT, "last output at a limit", as_bool=True)


class ScheduledPPIDController:
    """Cascaded P-PID per axis with gains from a :class:`GainSchedule` at the airspeed.

    Parameters
    ----------
    schedule
        the gain schedule (one breakpoint = constant gains, SHIF).
    dt
        control period [s].
    rate_limits
        limits of the rate references (roll, pitch, yaw) [rad/s].
    name
        controller name for reports.
    """

    def __init__(self, schedule: GainSchedule, dt: float = 0.004, *,
                 rate_limits: tuple[float, float, float] = (2.0, 2.0, 1.0),
                 name: str = "gs-shif", gains_path: Path | None = None) -> None:
        self.schedule = schedule
        self.name = name
        self.gains_path = gains_path if gains_path is not None else Path("<memory>")
        self.gains_sha256 = _sha256(gains_path) if gains_path is not None else ""
        g0 = schedule.gains_at(0.0)
        self._state = np.zeros((3, _N_STATE))
        self._const = np.zeros((3, _N_CONST))
        self.pids: list[CascadedPPID] = [
            _ArrayPPID(self._state, self._const, k, g0[ax], dt, wrap=(ax == "yaw"),
                       rate_limit=rl, output_limit=1e6)
            for k, (ax, rl) in enumerate(zip(AXES, rate_limits, strict=True))]
        # the compiled step runs while self.pids are still these three objects
        self._own = tuple(self.pids)
        self._out = np.zeros(3)
        self._gains_cache: dict[float, dict[str, PPIDGains]] = {}
        self._garr_cache: dict[int, tuple[dict[str, PPIDGains], NDArray[np.float64]]] = {}
        self._cached_schedule: GainSchedule | None = schedule

    def reset(self) -> None:
        """Clear the integrators of the three axes' P-PID loops."""
        pids, own = self.pids, self._own
        if len(pids) == 3 and pids[0] is own[0] and pids[1] is own[1] and pids[2] is own[2]:
            # CascadedPPID.reset() of the three, on their state array at once
            st = self._state
            st[:, _S_INTEGRAL:_S_EPREV + 1] = 0.0
            st[:, _S_RREF:] = 0.0
            return
        for p in pids:
            p.reset()

    def update(self, ref: NDArray[np.float64], att: NDArray[np.float64],
               rates: NDArray[np.float64], airspeed_m_s: float,
               sat_hi: Sequence[bool], sat_lo: Sequence[bool]) -> NDArray[np.float64]:
        """Moment demand for one control step.

        Parameters
        ----------
        ref, att : numpy.ndarray
            attitude reference and measured attitude, (roll, pitch, yaw) ZYX Euler angles (rad).
        rates : numpy.ndarray
            body rates p, q, r, FRD (rad/s).
        airspeed_m_s : float
            airspeed (m/s), the scheduling variable.
        sat_hi, sat_lo : sequence of bool
            per axis, the allocator saturated the moment at its upper / lower limit last step
            (anti-windup: the integrators do not move further that way).

        Returns
        -------
        numpy.ndarray
            moment demand (roll, pitch, yaw) about the body FRD axes (N m).
        """
        g = self._gains_cache.get(airspeed_m_s) if self._cached_schedule is self.schedule \
            else None
        if g is None:
            g = self._gains_at(airspeed_m_s)
        pids = self.pids
        own = self._own
        if (len(pids) == 3 and pids[0] is own[0] and pids[1] is own[1] and pids[2] is own[2]
                and type(ref) is np.ndarray and type(att) is np.ndarray
                and type(rates) is np.ndarray):
            # the three axes in one compiled call on the state array the pids view
            ga = self._garr_cache.get(id(g))
            if ga is None or ga[0] is not g:
                ga = self._gains_array(g)
            gr, gp, gy = g[AXES[0]], g[AXES[1]], g[AXES[2]]
            own[0].gains = gr
            own[1].gains = gp
            own[2].gains = gy
            out = self._out
            _ppid3_step(ref.astype(np.float64, copy=False), att.astype(np.float64, copy=False),
                        rates.astype(np.float64, copy=False), ga[1], self._state,
                        self._const, bool(sat_hi[0]), bool(sat_hi[1]), bool(sat_hi[2]),
                        bool(sat_lo[0]), bool(sat_lo[1]), bool(sat_lo[2]), out)
            return out.copy()
        rl, al, wl = _floats3(ref), _floats3(att), _floats3(rates)
        o3 = [0.0, 0.0, 0.0]
        for k, pid in enumerate(self.pids):
            gk = g[AXES[k]]
            before = pid.integral
            # pid.update(rl[k], al[k], wl[k], gk) inlined, statement for statement (the hot
            # path: two method calls per axis and step saved); tests/test_attitude.py checks
            # it against CascadedPPID.update bit for bit
            pid.gains = gk
            err = rl[k] - al[k]
            if pid.wrap:
                err = -((-err + math.pi) % TWO_PI - math.pi)  # wrap_angle
            r = gk.kp_angle * err + 0.0  # + rate_ff
            lim = pid.rate_limit
            if lim is not None:
                r = min(max(r, -lim), lim)
            # CascadedPPID.update_rate(r, wl[k])
            e = r - wl[k]
            e_prev = pid._e_prev
            de = e - e_prev
            tf = gk.tf_rate_s
            if tf == pid._tf_cached:
                a, b = pid._a, pid._b
            else:
                a, b = pid._filter_coeffs(tf)
            derivative = a * pid.derivative + b * gk.kd_rate * de
            pid.derivative = derivative
            dt = pid.dt
            dI = (0.5 * gk.ki_rate * dt * (e + e_prev) if pid.method == "tustin"
                  else gk.ki_rate * dt * e)
            p = gk.kp_rate * e
            integral = before
            u_min, u_max = pid.u_min, pid.u_max
            u_test = p + integral + dI + derivative
            if dI > 0.0 and u_test > u_max:
                dI = max(0.0, u_max - (u_test - dI))
            elif dI < 0.0 and u_test < u_min:
                dI = min(0.0, u_min - (u_test - dI))
            integral = min(max(integral + dI, u_min), u_max)
            pid.integral = integral
            o = p + integral + derivative
            pid.output_unsat = o
            pid.saturated = o >= u_max or o <= u_min
            o = min(max(o, u_min), u_max)
            pid._e_prev = e
            pid.rate_ref = r
            pid.output = o
            # anti-windup from the allocation's saturation
            di = integral - before
            if (di > 0.0 and sat_hi[k]) or (di < 0.0 and sat_lo[k]):
                o -= di
                pid.integral = before
            o3[k] = o
        out = self._out
        out[0], out[1], out[2] = o3
        return out.copy()

    def _gains_array(self, g: dict[str, PPIDGains]
                     ) -> tuple[dict[str, PPIDGains], NDArray[np.float64]]:
        """The (3, 5) array of ``g`` for the compiled step (kp_angle, kp_rate, ki_rate,
        kd_rate, tf_rate_s per axis), memoised on the dict (kept alive by the entry)."""
        if len(self._garr_cache) >= 20_000:
            self._garr_cache = {}
        arr = np.array([[float(g[ax].kp_angle), float(g[ax].kp_rate), float(g[ax].ki_rate),
                         float(g[ax].kd_rate), float(g[ax].tf_rate_s)] for ax in AXES])
        ga = (g, arr)
        self._garr_cache[id(g)] = ga
        return ga

    def _gains_at(self, airspeed_m_s: float) -> dict[str, PPIDGains]:
        """``schedule.gains_at`` memoised on the exact airspeed (the measured airspeed comes
        in 0.01 m/s steps, so values repeat; the gains of a value never change)."""
        if self._cached_schedule is not self.schedule or len(self._gains_cache) >= 20_000:
            self._gains_cache = {}
            self._cached_schedule = self.schedule
        g = self.schedule.gains_at(airspeed_m_s)
        if airspeed_m_s == airspeed_m_s:  # never a NaN key
            self._gains_cache[airspeed_m_s] = g
        return g


class LQRAttitudeController:
    """``tau = k_int * int(e) + k_angle * e - k_rate * rate`` per axis (see :mod:`.lqr`).

    Anti-windup: the integral term does not move in the direction of a saturated axis.
    """

    def __init__(self, gains: LQRGains, dt: float = 0.004, *, name: str = "lqr",
                 gains_path: Path | None = None) -> None:
        self.gains = gains
        self.dt = float(dt)
        self.name = name
        self.gains_path = gains_path if gains_path is not None else Path("<memory>")
        self.gains_sha256 = _sha256(gains_path) if gains_path is not None else ""
        self.integral_term = np.zeros(3)  # k_int * int(e) [N m], bumpless under scheduling
        self._gains_cache: dict[float, dict[str, LQRAxisGains]] = {}
        self._karr_cache: dict[int, tuple[dict[str, LQRAxisGains], NDArray[np.float64]]] = {}
        self._cached_gains: LQRGains | None = gains

    def reset(self) -> None:
        """Clear the integral terms of the three axes."""
        self.integral_term[:] = 0.0

    def update(self, ref: NDArray[np.float64], att: NDArray[np.float64],
               rates: NDArray[np.float64], airspeed_m_s: float,
               sat_hi: Sequence[bool], sat_lo: Sequence[bool]) -> NDArray[np.float64]:
        """Moment demand for one control step.

        Parameters
        ----------
        ref, att : numpy.ndarray
            attitude reference and measured attitude, (roll, pitch, yaw) ZYX Euler angles (rad).
        rates : numpy.ndarray
            body rates p, q, r, FRD (rad/s).
        airspeed_m_s : float
            airspeed (m/s), the scheduling variable.
        sat_hi, sat_lo : sequence of bool
            per axis, the allocator saturated the moment at its upper / lower limit last step
            (anti-windup: the integrators do not move further that way).

        Returns
        -------
        numpy.ndarray
            moment demand (roll, pitch, yaw) about the body FRD axes (N m).
        """
        g = self._gains_cache.get(airspeed_m_s) if self._cached_gains is self.gains else None
        if g is None:
            g = self._gains_at(airspeed_m_s)
        out = np.empty(3)
        it = self.integral_term
        if (type(ref) is np.ndarray and type(att) is np.ndarray and type(rates) is np.ndarray
                and type(it) is np.ndarray and it.dtype == _F64 and it.shape == (3,)):
            ka = self._karr_cache.get(id(g))
            if ka is None or ka[0] is not g:
                ka = self._gains_array(g)
            _lqr3_step(ref.astype(np.float64, copy=False), att.astype(np.float64, copy=False),
                       rates.astype(np.float64, copy=False), ka[1], self.dt, it,
                       bool(sat_hi[0]), bool(sat_hi[1]), bool(sat_hi[2]),
                       bool(sat_lo[0]), bool(sat_lo[1]), bool(sat_lo[2]), out)
            return out
        rl, al, wl = _floats3(ref), _floats3(att), _floats3(rates)
        for k, ax in enumerate(AXES):
            gk = g[ax]
            e = rl[k] - al[k]
            if k == 2:
                e = wrap_angle(e)
            dI = gk.k_int * e * self.dt
            if not ((dI > 0.0 and sat_hi[k]) or (dI < 0.0 and sat_lo[k])):
                it[k] += dI
            out[k] = gk.k_angle * e - gk.k_rate * wl[k] + it[k]
        return out

    def _gains_array(self, g: dict[str, LQRAxisGains]
                     ) -> tuple[dict[str, LQRAxisGains], NDArray[np.float64]]:
        """The (3, 3) array of ``g`` for the compiled step (k_int, k_angle, k_rate per axis),
        memoised on the dict (kept alive by the entry)."""
        if len(self._karr_cache) >= 20_000:
            self._karr_cache = {}
        arr = np.array([[float(g[ax].k_int), float(g[ax].k_angle), float(g[ax].k_rate)]
                        for ax in AXES])
        ka = (g, arr)
        self._karr_cache[id(g)] = ka
        return ka

    def _gains_at(self, airspeed_m_s: float) -> dict[str, LQRAxisGains]:
        """``gains.gains_at`` memoised on the exact airspeed (as the P-PID controller's: the
        measured airspeed comes in 0.01 m/s steps; the gains of a value never change)."""
        if self._cached_gains is not self.gains or len(self._gains_cache) >= 20_000:
            self._gains_cache = {}
            self._cached_gains = self.gains
        g = self.gains.gains_at(airspeed_m_s)
        if airspeed_m_s == airspeed_m_s:  # never a NaN key
            self._gains_cache[airspeed_m_s] = g
        return g


def make_controller(name: str, gains_dir: str | Path | None = None, dt: float = 0.004, *,
                    airframe_name: str | None = None,
                    airframe_sha256: str | None = None) -> AttitudeController:
    """Build the controller ``name`` (``gs-shif``, ``shif`` or ``lqr``) from its gain file.

    When ``airframe_name``/``airframe_sha256`` are given, the file must have been designed
    for that airframe. Raises :class:`ControllerError` with a clear message otherwise.
    """
    path = gains_file(name, gains_dir)
    if not path.is_file():
        where = "the shipped gains directory" if gains_dir is None else "--gains"
        raise ControllerError(
            f"controller {name!r}: gain file {path} not found in {where}; run the synthesis "
            "to produce it or pass a directory holding gs-shif.json, shif.json and lqr.json")
    if not (dt > 0 and math.isfinite(dt)):
        raise ControllerError(f"dt = {dt!r}: expected a positive control period in seconds")
    try:
        if name == "lqr":
            lq = LQRGains.load(path)
            lq.verify_airframe(airframe_name, airframe_sha256)
            return LQRAttitudeController(lq, dt, name=name, gains_path=path)
        sched = GainSchedule.load(path)
        sched.verify_airframe(airframe_name, airframe_sha256)
    except (GainScheduleError, LQRGainsError) as exc:
        raise ControllerError(f"controller {name!r}: {exc}") from None
    return ScheduledPPIDController(sched, dt, name=name, gains_path=path)
