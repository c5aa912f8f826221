"""Flight metrics of a run, as the paper's table 4 and a few more.

Computed only from what every runner has: each sample's :class:`NavState` (what the autopilot
flew on) and :class:`AutopilotStatus` (its references and mode). An in-process run and a SITL
run fed with the same samples therefore give identical metrics.

Over the transition window ``t >= window_start_s`` (default 20 s, when the transition is
commanded):

- ``rmse_altitude_m``: RMSE of ``altitude_ref - altitude`` (altitude above home = -NED z);
- ``rmse_roll_deg``, ``rmse_pitch_deg``, ``rmse_yaw_deg``: RMSE of the attitude tracking error
  ``reference - measured`` (ZYX Euler; yaw error wrapped to (-180, 180] deg);
- ``max_abs_{roll,pitch,yaw}_error_deg``: largest absolute tracking error;
- ``max_attitude_excursion_deg``: largest ``max(|roll|, |pitch|)`` (away from level);
- ``max_altitude_lost_m``: largest ``altitude_ref - altitude`` (0 if never below);

and over the whole run:

- ``transition_start_s``: first sample in FRONT_TRANSITION; ``transition_complete_s``: first
  sample in FIXED_WING (sim seconds, None if never); ``transition_duration_s``;
- ``quad_chute``: a front transition that ended back in HOVER;
- ``final_altitude_m``, ``final_altitude_error_m`` (last sample), ``final_airspeed_m_s``,
  ``final_{roll,pitch,yaw}_deg`` (mean over the last second);
- ``crashed``: non-finite state, ground contact in the air (altitude below 0.5 m above the
  altitude at the first armed sample, in a flying mode, after having been above 2 m), or an
  attitude beyond 60 deg of roll or pitch.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.base.rotation import quat_to_euler
from vtolftc.protocols.hil import NavState
from vtolftc.telemetry import metrics_kernel as mk
from vtolftc.telemetry.autopilot_status import FlightMode
from vtolftc.telemetry.samples import TelemetrySample

__all__ = ["CRASH_ATTITUDE_DEG", "MetricsAccumulator", "compute_metrics", "is_crash"]

CRASH_ATTITUDE_DEG = 60.0
_CRASH_ATTITUDE_RAD = math.radians(CRASH_ATTITUDE_DEG)
_RAD_TO_DEG = math.degrees(1.0)  # what math.degrees multiplies by (CPython)
_F64 = np.dtype(np.float64)
_TAIL_CAPACITY = 512  # the tail ring's first size: one second at up to 511 samples/s


def is_crash(altitude_above_ground_m: float, roll_rad: float, pitch_rad: float,
             flying: bool, was_high: bool) -> bool:
    """The crash criterion of the module docstring for one sample."""
    return _is_crash(altitude_above_ground_m, roll_rad, pitch_rad, flying, was_high)


def _is_crash(h: float, roll: float, pitch: float, flying: bool, was_high: bool) -> bool:
    isf = math.isfinite
    if not (isf(h) and isf(roll) and isf(pitch)):
        return True
    if abs(roll) > _CRASH_ATTITUDE_RAD or abs(pitch) > _CRASH_ATTITUDE_RAD:
        return True
    return flying and was_high and h < 0.5


class MetricsAccumulator:
    """Streaming metrics: ``add(sample)`` per control step, ``result()`` at any time.

    ``add`` is O(1) and allocation-free: the per-sample arithmetic is one compiled call
    (:func:`~vtolftc.telemetry.metrics_kernel.metrics_step`, bit-identical to its Python
    reference) on a flat float64 state and a ring buffer of the last second's attitudes (grown
    by doubling when a higher sample rate needs it). It runs every control step of every run,
    in-process and in SITL.
    """

    def __init__(self, window_start_s: float = 20.0) -> None:
        self.window_start_s = float(window_start_s)
        self._s = mk.new_state(self.window_start_s)
        self._tail = np.zeros((_TAIL_CAPACITY, 4))

    @property
    def kernel_arrays(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(state, tail)``, the arrays :meth:`add_step` hands
        :func:`~vtolftc.telemetry.metrics_kernel.metrics_step`, for a caller that fuses that
        kernel into its own compiled call (the in-process runner); when the kernel answers 0
        (the tail ring full, nothing changed) that caller calls :meth:`add_step`, which grows
        the ring. Read them again before each call (growing replaces the tail)."""
        return self._s, self._tail

    # the running values under the names the accumulator has always offered
    @property
    def n(self) -> int:
        """Samples added."""
        return int(self._s[mk.S_N])

    @property
    def n_win(self) -> int:
        """Samples added in the window."""
        return int(self._s[mk.S_N_WIN])

    @property
    def crashed(self) -> bool:
        """A sample met the crash criterion."""
        return bool(self._s[mk.S_CRASHED] != 0.0)

    @property
    def crash_time_s(self) -> float | None:
        """Time of the first crashed sample [s], or None."""
        return self._opt(mk.S_CRASHED, mk.S_CRASH_T)

    @property
    def transition_start_s(self) -> float | None:
        """Time of the first FRONT_TRANSITION sample [s], or None."""
        return self._opt(mk.S_HAS_TS, mk.S_TS)

    @property
    def transition_complete_s(self) -> float | None:
        """Time of the first FIXED_WING sample [s], or None."""
        return self._opt(mk.S_HAS_TC, mk.S_TC)

    @property
    def quad_chute(self) -> bool:
        """A front transition ended back in HOVER."""
        return bool(self._s[mk.S_QUAD_CHUTE] != 0.0)

    @property
    def t_last(self) -> float:
        """Time of the last sample [s] (0 before the first)."""
        return float(self._s[mk.S_T_LAST])

    def _opt(self, flag: int, value: int) -> float | None:
        return float(self._s[value]) if self._s[flag] != 0.0 else None

    def add(self, s: TelemetrySample) -> None:
        """Add one control step: errors, peaks, transition and crash detection."""
        st = s.status
        self.add_step(s.time_usec, s.nav, st.mode, st.armed, st.attitude_ref_rad,
                      st.altitude_ref_m)

    def add_step(self, time_usec: int, nav: NavState, mode: FlightMode | int, armed: bool,
                 attitude_ref_rad: NDArray[np.float64] | Sequence[float],
                 altitude_ref_m: float,
                 euler_rad: tuple[float, float, float] | None = None) -> bool:
        """:meth:`add` from the sample's parts (the in-process runner's path: no
        :class:`AutopilotStatus` built when nobody else reads it); returns :attr:`crashed`
        (so that the runner's stop test needs no call of its own).

        Parameters
        ----------
        time_usec : int
            Sample time [us].
        nav : NavState
            What the autopilot flew on.
        mode, armed, attitude_ref_rad, altitude_ref_m
            The :class:`AutopilotStatus` fields of the same names (roll, pitch, yaw
            references [rad]; altitude reference above home [m]); read, never kept.
        euler_rad : tuple, optional
            ``quat_to_euler(nav.q_wxyz)`` when the caller has it already [rad].

        Returns
        -------
        bool
            :attr:`crashed` after this sample.
        """
        roll, pitch, yaw = quat_to_euler(nav.q_wxyz) if euler_rad is None else euler_rad
        pos = nav.pos_ned_m
        if type(pos) is not np.ndarray or pos.dtype != _F64 or pos.shape != (3,):
            pos = np.array((float(pos[0]), float(pos[1]), float(pos[2])))
        ref = attitude_ref_rad
        if type(ref) is not np.ndarray or ref.dtype != _F64 or ref.shape != (3,):
            ref = np.array((float(ref[0]), float(ref[1]), float(ref[2])))
        if type(mode) is not FlightMode:
            mode = FlightMode(mode)
        while True:
            r = mk.metrics_step(self._s, self._tail, time_usec, pos, roll, pitch, yaw,
                                int(mode), bool(armed), ref, float(altitude_ref_m),
                                float(nav.airspeed_m_s))
            if r:
                return r == 2  # the kernel's "crashed" (s[S_CRASHED]), no read of it here
            self._grow_tail()

    def _grow_tail(self) -> None:
        """Double the tail ring, its samples moved to the start in order."""
        s = self._s
        head, n = int(s[mk.S_HEAD]), int(s[mk.S_LEN])
        cap = self._tail.shape[0]
        new = np.zeros((2 * cap, 4))
        new[:n] = self._tail[(head + np.arange(n)) % cap]
        self._tail = new
        s[mk.S_HEAD] = 0.0

    def _tail_rows(self) -> list[tuple[float, float, float, float]]:
        """The tail's samples, oldest first, as Python floats."""
        s = self._s
        head, n = int(s[mk.S_HEAD]), int(s[mk.S_LEN])
        cap = self._tail.shape[0]
        rows = self._tail[(head + np.arange(n)) % cap].tolist()
        return [(r[0], r[1], r[2], r[3]) for r in rows]

    def result(self) -> dict[str, Any]:
        """Metrics so far: RMSE and peak errors, transition timing, crash and quad-chute flags."""
        s = self._s
        n_win = self.n_win
        n = max(n_win, 1)
        rm = [math.sqrt(x / n) if n_win else math.nan
              for x in s[mk.S_SE:mk.S_SE + 4].tolist()]
        tail = self._tail_rows() or [(0.0, math.nan, math.nan, math.nan)]
        ts, tc = self.transition_start_s, self.transition_complete_s
        dur = tc - ts if tc is not None and ts is not None else None
        last = ((float(s[mk.S_LAST_H]), float(s[mk.S_LAST_EH]), float(s[mk.S_LAST_AIR]))
                if s[mk.S_HAS_LAST] != 0.0 else (math.nan, math.nan, math.nan))
        mx = s[mk.S_MAX:mk.S_MAX + 3].tolist()
        return {
            "window_start_s": self.window_start_s,
            "samples": self.n,
            "samples_in_window": n_win,
            "duration_s": self.t_last,
            "rmse_altitude_m": rm[0],
            "rmse_roll_deg": rm[1],
            "rmse_pitch_deg": rm[2],
            "rmse_yaw_deg": rm[3],
            "max_abs_roll_error_deg": mx[0],
            "max_abs_pitch_error_deg": mx[1],
            "max_abs_yaw_error_deg": mx[2],
            "max_attitude_excursion_deg": float(s[mk.S_MAX_TILT]) * _RAD_TO_DEG,
            "max_altitude_lost_m": float(s[mk.S_MAX_LOST]),
            "transition_start_s": ts,
            "transition_complete_s": tc,
            "transition_duration_s": dur,
            "quad_chute": self.quad_chute,
            "final_altitude_m": last[0],
            "final_altitude_error_m": last[1],
            "final_airspeed_m_s": last[2],
            "final_roll_deg": sum(r[1] for r in tail) / len(tail),
            "final_pitch_deg": sum(r[2] for r in tail) / len(tail),
            "final_yaw_deg": sum(r[3] for r in tail) / len(tail),
            "crashed": self.crashed,
            "crash_time_s": self.crash_time_s,
        }


def compute_metrics(samples: Iterable[TelemetrySample], window_start_s: float = 20.0,
                    ) -> dict[str, Any]:
    """Metrics of a sequence of samples (see the module docstring)."""
    acc = MetricsAccumulator(window_start_s)
    for s in samples:
        acc.add(s)
    return acc.result()
