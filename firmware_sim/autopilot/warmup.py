"""Warm start: compile (or load from numba's cache) every compiled path of the autopilot.

The autopilot's compiled kernels (the allocation's,
:mod:`vtolftc.firmware_sim.autopilot.allocation`, and the attitude laws',
:mod:`vtolftc.firmware_sim.autopilot.control_kernels`) are compiled by numba at their first call
*for the argument types of that call*: a later call with another type (a writable instead
of a read-only array, another layout) compiles a second specialisation, on a fresh install
1-2 s in which the control loop stands still (measured in flight: the vehicle's output
watchdog cut the rotors). :func:`warm_up` flies a throwaway
autopilot of the same configuration through a synthetic flight that visits every flight mode
and every allocation path (on the ground, armed, take-off, hover, front transition, fixed-wing
with the lift rotors bounded and then as the weighted reserve, back transition, hover, land,
disarmed after landing) on made-up navigation data, with the same argument types as a real
flight, so that every kernel is compiled or loaded before the real autopilot reports itself
ready. It never touches the real autopilot. The allocator hands its kernels the same array
types whatever the caller passes (see ``ActiveSetAllocator.allocate``), so the specialisations
prepared here are the only ones a flight needs.

:func:`compiled_specialisations` counts the specialisations of every numba dispatcher of the
loaded ``vtolftc`` modules; the autopilot process records them when it reports ready and
reports any that appeared afterwards (``autopilot_summary.json``, ``numba``), and a test flies
every mode and checks that none did.
"""

from __future__ import annotations

import gc
import math
import sys
from collections.abc import Callable

import numpy as np

from vtolftc.firmware_sim.autopilot.interface import AutopilotAPI, FlightMode, NavState

__all__ = ["compiled_specialisations", "freeze_heap", "new_specialisations", "warm_up"]

_NAN = math.nan
_NAN7 = [_NAN] * 7


def warm_up(make_autopilot: Callable[[], AutopilotAPI], steps: int = 400,
            dt_usec: int = 4000, stop: Callable[[], bool] | None = None) -> int:
    """Step a fresh autopilot from ``make_autopilot`` through a synthetic flight of every mode.

    The flight: 5 steps on the ground, arm, take-off to ``MIS_TAKEOFF_ALT`` (climbing), hover,
    front transition (airspeed rising), fixed-wing until the lift rotors have ramped down and
    become the weighted reserve (``VT_TRANS_P2_DUR`` plus 1 s), back transition (airspeed
    falling), hover, land, touch down and disarm. Each phase lasts at least ``steps // 8``
    steps and ends when its mode is reached (at most ``4 * steps`` steps each), so the
    navigation data only has to be plausible, not physical.

    Parameters
    ----------
    make_autopilot
        builds an autopilot configured like the real one.
    steps
        scale of the flight, control steps (default 400: about 3600 steps in all, 1-2 s
        once compiled).
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
    alt = 0.0
    v_n = 0.0
    dt = dt_usec * 1e-6
    phase = max(1, steps // 8)
    cap = 4 * max(1, steps)

    def step() -> bool:
        nonlocal t, n
        if stop is not None and stop():
            return False
        ap.step(NavState(t, q.copy(), w.copy(), np.array([0.0, 0.0, -alt]),
                         np.array([v_n, 0.0, 0.0]), abs(v_n)))
        t += dt_usec
        n += 1
        return True

    def fly(until: Callable[[], bool], climb_m_s: float = 0.0, accel_m_s2: float = 0.0,
            top_m: float = math.inf, min_steps: int = phase) -> bool:
        nonlocal alt, v_n
        for k in range(cap):
            if k >= min_steps and until():
                return True
            alt = min(top_m, max(0.0, alt + climb_m_s * dt))
            v_n = min(v_top, max(0.0, v_n + accel_m_s2 * dt))
            if not step():
                return False
        return True

    def mode() -> FlightMode:
        return ap.status().mode

    for _ in range(5):  # on the ground: navigation data first, then arming is allowed
        if not step():
            return n
    ap.command(400, [1.0, *_NAN7[:6]])
    ap.command(22, _NAN7)  # MIS_TAKEOFF_ALT above home (param7 is AMSL: no number here)
    top = float(ap.params.get("MIS_TAKEOFF_ALT"))
    ramp_s = float(ap.params.get("VT_TRANS_P2_DUR"))
    v_top = float(ap.params.get("VT_ARSP_TRANS")) + 5.0  # beyond the transition airspeed
    accel = v_top / 4.0  # there within 4 s, whatever the airframe's transition airspeed
    if not fly(lambda: mode() == FlightMode.HOVER, 15.0, 0.0, top):       # take-off
        return n
    if not fly(lambda: True, 0.0, 0.0, top):                               # hover
        return n
    ap.command(3000, [4.0, *_NAN7[:6]])                                    # front transition
    if not fly(lambda: mode() == FlightMode.FIXED_WING, 0.0, accel, top):
        return n
    fw_steps = int((ramp_s + 1.0) / dt) + phase  # rotors bounded, then the reserve
    if not fly(lambda: True, 0.0, 2.0, top, fw_steps):
        return n
    ap.command(3000, [3.0, *_NAN7[:6]])                                    # back transition
    if not fly(lambda: mode() == FlightMode.HOVER, 0.0, -accel, top):
        return n
    if not fly(lambda: True, 0.0, -accel, top):                            # hover
        return n
    ap.command(21, _NAN7)                                                  # land
    fly(lambda: not ap.status().armed, -15.0, 0.0, top)
    return n


def freeze_heap() -> None:
    """Collect garbage, then freeze every object alive out of the garbage collector.

    numba's compiler leaves some 10^5 long-lived objects; a full collection over them took
    0.1-0.26 s of CPU inside a control step. Called once after :func:`warm_up`, before the
    first real control step (``gc.freeze``: later collections skip these objects).
    """
    gc.collect()
    gc.freeze()


def _dispatchers(prefix: str) -> dict[str, object]:
    from numba.core.dispatcher import Dispatcher

    out: dict[str, object] = {}
    for name, mod in list(sys.modules.items()):
        if mod is None or not (name == prefix.rstrip(".") or name.startswith(prefix)):
            continue
        for obj in list(vars(mod).values()):
            if isinstance(obj, Dispatcher):
                f = obj.py_func
                out[f"{f.__module__}.{f.__qualname__}"] = obj
    return out


def compiled_specialisations(prefix: str = "vtolftc.") -> dict[str, list[str]]:
    """The compiled specialisations of every numba dispatcher in the loaded modules.

    Parameters
    ----------
    prefix
        module-name prefix of the modules searched (default every ``vtolftc`` module).

    Returns
    -------
    dict
        ``module.function`` -> the argument-type signatures compiled (or loaded from the
        cache) so far, as text, sorted.
    """
    return {k: sorted(str(sig) for sig in d.signatures)  # type: ignore[attr-defined]
            for k, d in sorted(_dispatchers(prefix).items())}


def new_specialisations(before: dict[str, list[str]],
                        after: dict[str, list[str]]) -> dict[str, list[str]]:
    """The specialisations in ``after`` that ``before`` lacks (``module.function`` ->
    signatures); empty when nothing was compiled in between."""
    out = {}
    for k, sigs in after.items():
        old = set(before.get(k, ()))
        extra = [s for s in sigs if s not in old]
        if extra:
            out[k] = extra
    return out
