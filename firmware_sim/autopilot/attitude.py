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

import numpy as np
from numpy.typing import NDArray

from vtolftc.firmware_sim.autopilot import control_kernels as ck
from vtolftc.firmware_sim.autopilot.lqr import LQRAxisGains, LQRGains, LQRGainsError
from vtolftc.firmware_sim.autopilot.pid import CascadedPPID, PPIDGains, gains_row
from vtolftc.firmware_sim.autopilot.schedule import GainSchedule, GainScheduleError
from vtolftc.rotation import ATTITUDE_AXES

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


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


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
        self._state = np.zeros((3, ck.N_STATE))
        self._const = np.zeros((3, ck.N_CONST))
        #: the three axes (roll, pitch, yaw), views of the arrays the compiled step updates
        self.pids: tuple[CascadedPPID, ...] = tuple(
            CascadedPPID(g0[ax], dt, wrap=(ax == "yaw"), rate_limit=rl, output_limit=1e6,
                         state=self._state, const=self._const, row=k)
            for k, (ax, rl) in enumerate(zip(ATTITUDE_AXES, rate_limits, strict=True)))
        self._out = np.zeros(3)
        self._gains_cache: dict[float, dict[str, PPIDGains]] = {}
        self._garr_cache: dict[int, tuple[dict[str, PPIDGains], NDArray[np.float64]]] = {}
        self._cached_schedule: GainSchedule | None = schedule

    def reset(self) -> None:
        """Clear the integrators of the three axes' P-PID loops (``CascadedPPID.reset``)."""
        st = self._state
        st[:, ck.S_INTEGRAL:ck.S_E_PREV + 1] = 0.0
        st[:, ck.S_RATE_REF:] = 0.0

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
        ga = self._garr_cache.get(id(g))
        if ga is None or ga[0] is not g:
            ga = self._gains_array(g)
        own = self.pids
        own[0].gains = g[ATTITUDE_AXES[0]]
        own[1].gains = g[ATTITUDE_AXES[1]]
        own[2].gains = g[ATTITUDE_AXES[2]]
        out = self._out
        ck.ppid3_step(np.asarray(ref, dtype=np.float64), np.asarray(att, dtype=np.float64),
                      np.asarray(rates, dtype=np.float64), ga[1], self._state, self._const,
                      bool(sat_hi[0]), bool(sat_hi[1]), bool(sat_hi[2]),
                      bool(sat_lo[0]), bool(sat_lo[1]), bool(sat_lo[2]), out)
        return out.copy()

    def _gains_array(self, g: dict[str, PPIDGains]
                     ) -> tuple[dict[str, PPIDGains], NDArray[np.float64]]:
        """The (3, 5) array of ``g`` for the compiled step (kp_angle, kp_rate, ki_rate,
        kd_rate, tf_rate_s per axis), memoised on the dict (kept alive by the entry)."""
        if len(self._garr_cache) >= 20_000:
            self._garr_cache = {}
        arr = np.array([gains_row(g[ax]) for ax in ATTITUDE_AXES])
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
        ka = self._karr_cache.get(id(g))
        if ka is None or ka[0] is not g:
            ka = self._gains_array(g)
        out = np.empty(3)
        ck.lqr3_step(np.asarray(ref, dtype=np.float64), np.asarray(att, dtype=np.float64),
                     np.asarray(rates, dtype=np.float64), ka[1], self.dt, self.integral_term,
                     bool(sat_hi[0]), bool(sat_hi[1]), bool(sat_hi[2]),
                     bool(sat_lo[0]), bool(sat_lo[1]), bool(sat_lo[2]), out)
        return out

    def _gains_array(self, g: dict[str, LQRAxisGains]
                     ) -> tuple[dict[str, LQRAxisGains], NDArray[np.float64]]:
        """The (3, 3) array of ``g`` for the compiled step (k_int, k_angle, k_rate per axis),
        memoised on the dict (kept alive by the entry)."""
        if len(self._karr_cache) >= 20_000:
            self._karr_cache = {}
        arr = np.array([[float(g[ax].k_int), float(g[ax].k_angle), float(g[ax].k_rate)]
                        for ax in ATTITUDE_AXES])
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
