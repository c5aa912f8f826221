"""Warm start: compile (or load from numba's cache) every compiled path of the autopilot.

The allocation's compiled kernels (:mod:`vtolftc.firmware_sim.autopilot.allocation`) are
compiled by numba at their first call; on a fresh install that first call (the first
allocation after takeoff) took 10-21 s, long enough for a real-time vehicle to give up.
:func:`warm_up` flies a throwaway autopilot of the same configuration through a short
synthetic take-off (on the ground, armed, climbing, hovering, then a front transition, so every
mode's allocation runs) on made-up navigation data, with the same argument types as a real
flight, so that every kernel is compiled or loaded before the real autopilot reports itself
ready. It never touches the real autopilot.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from vtolftc.firmware_sim.autopilot.interface import AutopilotAPI, NavState

__all__ = ["warm_up"]

_NAN = math.nan


def warm_up(make_autopilot: Callable[[], AutopilotAPI], steps: int = 400,
            dt_usec: int = 4000, stop: Callable[[], bool] | None = None) -> int:
    """Step a fresh autopilot from ``make_autopilot`` through a synthetic flight.

    Parameters
    ----------
    make_autopilot
        builds an autopilot configured like the real one.
    steps
        control steps after the take-off command (half climbing, the rest after a
        transition command).
    dt_usec
        control period, us.
    stop
        checked every step; True ends the warm-up early (a stop signal).

    Returns
    -------
    int
        The number of control steps taken.
    """
    ap = make_autopilot()
    q = np.array([1.0, 0.0, 0.0, 0.0])
    w = np.zeros(3)
    t = 0
    n = 0

    def nav(alt_m: float, v_n: float) -> NavState:
        return NavState(t, q.copy(), w.copy(), np.array([0.0, 0.0, -alt_m]),
                        np.array([v_n, 0.0, 0.0]), abs(v_n))

    for _ in range(5):  # on the ground: navigation data first, then arming is allowed
        ap.step(nav(0.0, 0.0))
        t += dt_usec
        n += 1
    ap.command(400, [1.0, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN])
    ap.command(22, [_NAN] * 7)  # MIS_TAKEOFF_ALT above home (param7 is AMSL: no number here)
    for k in range(steps):
        if stop is not None and stop():
            break
        alt = min(10.0, 0.02 * k)
        if k == steps // 2:
            ap.command(3000, [4.0, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN])
        v_n = 0.0 if k < steps // 2 else 0.05 * (k - steps // 2)
        ap.step(nav(alt, v_n))
        t += dt_usec
        n += 1
    return n
