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
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from vtolftc.base.rotation import ATTITUDE_AXES
from vtolftc.firmware_sim.autopilot import control_kernels as ck
from vtolftc.firmware_sim.autopilot.lqr import LQRAxisGains, LQRGains, LQRGainsError
from vtolftc.firmware_sim.autopilot.pid import CascadedPPID, PPIDGains, gains_row
from vtolftc.firmware_sim.autopilot.schedule import GainSchedule, GainScheduleError

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


def _lqr_row(g: LQRAxisGains) -> NDArray[np.float64]:
    """One axis of LQR gains as the kernel's row: k_int, k_angle, k_rate."""
    return np.array([float(g.k_int), float(g.k_angle), float(g.k_rate)])


_F64 = np.dtype(np.float64)


def _f64(a: Any) -> NDArray[np.float64]:
    """``np.asarray(a, dtype=np.float64)``, with a fast exit for a float64 array."""
    if type(a) is np.ndarray and a.dtype is _F64:
        return a
    return np.asarray(a, dtype=np.float64)


MEMO_ENTRIES = 256
"""Airspeeds (and gain sets) a :class:`_GainMemo` holds at most (about 0.2 MB)."""


class _GainMemo:
    """A gain table's gains at an airspeed (``table.gains_at``) and their (3, n) kernel array
    (the LQR's; the P-PID schedule is interpolated by ``control_kernels.scheduled_gains``),
    memoised: the measured airspeed comes in 0.01 m/s steps, so values repeat, and the gains
    of a value never change. Starts afresh when the table object is replaced, and when it
    holds :data:`MEMO_ENTRIES` airspeeds: the scheduling airspeed is low-passed, so in a
    transition almost every step is a new value, and an unbounded (or 20 000-entry) memo grew
    the autopilot by about 300 KB per simulated second (issue 24)."""

    def __init__(self, row: Callable[[Any], NDArray[np.float64]]) -> None:
        self._row = row  # a module-level function, so a controller still pickles
        self._table: object = None
        self._by_speed: dict[float, dict[str, Any]] = {}
        self._by_gains: dict[int, tuple[dict[str, Any], NDArray[np.float64]]] = {}

    def at(self, table: GainSchedule | LQRGains, airspeed_m_s: float
           ) -> tuple[dict[str, Any], NDArray[np.float64]]:
        """``(gains by axis, kernel array)`` at ``airspeed_m_s`` [m/s]."""
        if table is not self._table or len(self._by_speed) >= MEMO_ENTRIES:
            self._by_speed = {}
            self._table = table
        g = self._by_speed.get(airspeed_m_s)
        if g is None:
            g = table.gains_at(airspeed_m_s)
            if airspeed_m_s == airspeed_m_s:  # never a NaN key
                self._by_speed[airspeed_m_s] = g
        ga = self._by_gains.get(id(g))
        if ga is None or ga[0] is not g:  # keyed on the dict, kept alive by the entry
            if len(self._by_gains) >= MEMO_ENTRIES:
                self._by_gains = {}
            ga = (g, np.array([self._row(g[ax]) for ax in ATTITUDE_AXES]))
            self._by_gains[id(g)] = ga
        return ga


class ScheduledAxis(CascadedPPID):
    """One axis of a :class:`ScheduledPPIDController`: a :class:`CascadedPPID` whose ``gains``
    are also a view, of row ``row`` of the controller's gains array (the gains the compiled
    step used last, scheduled at its airspeed; written there by
    ``control_kernels.scheduled_gains``, not rebuilt as Python objects every step).

    Parameters
    ----------
    gains, dt
        As :class:`CascadedPPID` (``gains`` written into the row).
    gains_array
        The controller's gains array, shape (n, 5) (``control_kernels.G_*`` columns).
    **kwargs
        :class:`CascadedPPID`'s keyword arguments (``wrap``, ``rate_limit``, ``state``,
        ``const``, ``row``, ...).
    """

    def __init__(self, gains: PPIDGains, dt: float, *, gains_array: NDArray[np.float64],
                 **kwargs: Any) -> None:
        self._gains_array = gains_array
        super().__init__(gains, dt, **kwargs)

    @property  # type: ignore[override]
    def gains(self) -> PPIDGains:
        """The gains of this axis' row (a fresh :class:`PPIDGains` on each read)."""
        return PPIDGains(*self._gains_array[self._row].tolist())

    @gains.setter
    def gains(self, g: PPIDGains) -> None:
        self._gains_array[self._row] = gains_row(g)


class _GainFileController:
    """What every controller records of its gain file: ``name``, ``gains_path`` and the
    file's ``gains_sha256`` (empty for gains made in memory)."""

    def __init__(self, name: str, gains_path: Path | None) -> None:
        self.name = name
        self.gains_path = gains_path if gains_path is not None else Path("<memory>")
        self.gains_sha256 = (hashlib.sha256(gains_path.read_bytes()).hexdigest()
                             if gains_path is not None else "")


class ScheduledPPIDController(_GainFileController):
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
        super().__init__(name, gains_path)
        self.schedule = schedule
        g0 = schedule.gains_at(0.0)
        #: gains, state, constants and output in one array (the packed kernel's ``ws``);
        #: ``_gains``, ``_state``, ``_const`` and ``_out`` are views of it
        self._ws = np.zeros(ck.W_SIZE)
        self._link_views()
        #: the three axes (roll, pitch, yaw), views of the arrays the compiled step updates
        self.pids: tuple[CascadedPPID, ...] = tuple(
            ScheduledAxis(g0[ax], dt, wrap=(ax == "yaw"), rate_limit=rl, output_limit=1e6,
                          state=self._state, const=self._const, gains_array=self._gains,
                          row=k)
            for k, (ax, rl) in enumerate(zip(ATTITUDE_AXES, rate_limits, strict=True)))

    def _link_views(self) -> None:
        """``_gains`` (this step's gains, written by the kernel), ``_state``, ``_const`` and
        ``_out`` as views of the workspace ``_ws``, and ``kernel_arrays``: ``(gains, state,
        const, out)``, the arrays of the compiled step (``control_kernels.
        scheduled_ppid3_step``) for a caller that steps it directly: this step's gains
        (3, 5), the P-PID state (3, N_STATE), the constants (3, N_CONST), the output (3,)
        [N m]. The axes keep the whole state and constants arrays (``CascadedPPID``)."""
        ws = self._ws
        self._gains = ws[ck.W_GAINS:ck.W_STATE].reshape(3, ck.N_GAINS)
        self._state = ws[ck.W_STATE:ck.W_CONST].reshape(3, ck.N_STATE)
        self._const = ws[ck.W_CONST:ck.W_OUT].reshape(3, ck.N_CONST)
        self._out = ws[ck.W_OUT:ck.W_SIZE]
        self.kernel_arrays = (self._gains, self._state, self._const, self._out)
        #: the workspace itself (``control_kernels.scheduled_ppid3_step_packed``'s ``ws``)
        self.kernel_ws = ws
        for pid in getattr(self, "pids", ()):
            pid._state, pid._const, pid._gains_array = self._state, self._const, self._gains

    def __setstate__(self, state: dict[str, Any]) -> None:
        """A copied or unpickled controller (numpy copies every view on its own) links its
        arrays, and its axes', to its own workspace again."""
        self.__dict__.update(state)
        self._link_views()

    def reset(self) -> None:
        """Clear the integrators of the three axes' P-PID loops (``CascadedPPID.reset``)."""
        st = self._state
        st[:, ck.S_INTEGRAL:ck.S_E_PREV + 1] = 0.0
        st[:, ck.S_RATE_REF:] = 0.0

    def update(self, ref: NDArray[np.float64], att: NDArray[np.float64],
               rates: NDArray[np.float64], airspeed_m_s: float,
               sat_hi: Sequence[bool], sat_lo: Sequence[bool]) -> NDArray[np.float64]:
        """Moment demand for one control step [N m]; parameters and result as
        :meth:`AttitudeController.update`."""
        bp, rows, slopes = self.schedule.kernel_tables
        out = self._out
        ck.scheduled_ppid3_step(bp, rows, slopes, float(airspeed_m_s), _f64(ref), _f64(att),
                                _f64(rates), self._gains, self._state, self._const,
                                bool(sat_hi[0]), bool(sat_hi[1]), bool(sat_hi[2]),
                                bool(sat_lo[0]), bool(sat_lo[1]), bool(sat_lo[2]), out)
        return out.copy()


class LQRAttitudeController(_GainFileController):
    """``tau = k_int * int(e) + k_angle * e - k_rate * rate`` per axis (see :mod:`.lqr`).

    Anti-windup: the integral term does not move in the direction of a saturated axis.
    """

    def __init__(self, gains: LQRGains, dt: float = 0.004, *, name: str = "lqr",
                 gains_path: Path | None = None) -> None:
        super().__init__(name, gains_path)
        self.gains = gains
        self.dt = float(dt)
        self.integral_term = np.zeros(3)  # k_int * int(e) [N m], bumpless under scheduling
        self._memo = _GainMemo(_lqr_row)

    def reset(self) -> None:
        """Clear the integral terms of the three axes."""
        self.integral_term[:] = 0.0

    def update(self, ref: NDArray[np.float64], att: NDArray[np.float64],
               rates: NDArray[np.float64], airspeed_m_s: float,
               sat_hi: Sequence[bool], sat_lo: Sequence[bool]) -> NDArray[np.float64]:
        """Moment demand for one control step [N m]; parameters and result as
        :meth:`AttitudeController.update`."""
        karr = self._memo.at(self.gains, airspeed_m_s)[1]
        out = np.empty(3)
        ck.lqr3_step(np.asarray(ref, dtype=np.float64), np.asarray(att, dtype=np.float64),
                     np.asarray(rates, dtype=np.float64), karr, self.dt, self.integral_term,
                     bool(sat_hi[0]), bool(sat_hi[1]), bool(sat_hi[2]),
                     bool(sat_lo[0]), bool(sat_lo[1]), bool(sat_lo[2]), out)
        return out


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
