"""The in-process runner's part of a control step after the autopilot, in one compiled call.

Each control step of :func:`~vtolftc.runners.scenario.run_scenario` (no observer, no state
noise, no HIL delay) ends with three compiled kernels that used to be three Python calls,
each with its wrapper's checks and argument conversions: the flight metrics' sample
(:func:`~vtolftc.telemetry.metrics_kernel.metrics_step`), the vehicle's batch of physics
steps on the wire-rounded commands (the kernel of :meth:`Vehicle.step
<vtolftc.firmware_sim.vehicle.model.Vehicle.step>`) and, on the state that batch leaves, the
HIL round trip of the next step (:class:`~vtolftc.protocols.hil.HilRoundTrip`'s kernel).
:func:`runner_tail_step` calls the same three kernels on the same arguments in the same
order, so every flight keeps its bits (``benchmarks/command_digest.py``).
"""

from __future__ import annotations

import numba

from vtolftc.base.nrt import borrowed
from vtolftc.firmware_sim.vehicle.model import packed_views, take_and_step_packed
from vtolftc.protocols.hil import round_trip_kernel
from vtolftc.telemetry.metrics_kernel import metrics_step

__all__ = ["runner_tail_step"]


@numba.njit(cache=True)
def runner_tail_step(s, tail, time_usec, pos, roll, pitch, yaw, mode, armed, ref, alt_ref,
                     airspeed, u, ws, stuck, n, dt, buf, layout, flags, home,
                     nav_next):  # pragma: no cover - compiled
    """The metrics' sample, the vehicle's ``n`` physics steps and the next HIL round trip.

    Parameters
    ----------
    s, tail, time_usec, pos, roll, pitch, yaw, mode, armed, ref, alt_ref, airspeed
        :func:`~vtolftc.telemetry.metrics_kernel.metrics_step`'s arguments (the
        accumulator's ``kernel_arrays``; the sample at ``time_usec`` [us], position NED [m],
        ZYX Euler angles [rad], ``FlightMode`` value, armed flag, attitude reference [rad],
        altitude reference [m], airspeed [m/s]).
    u
        (n_u,) float64: the autopilot's commands (rounded as the wire carries them).
    ws, stuck, n, dt, buf, layout, flags
        The vehicle's compiled control step's (``Vehicle.control_step_args``; ``n`` physics
        steps of ``dt`` [s]).
    home
        (5,) ``HilRoundTrip.kernel_home``.
    nav_next
        (14,) float64: receives the next step's decoded navigation state (quaternion, body
        rates, position NED, velocity NED: ``HilRoundTrip``'s 13 entries) and, at index 13,
        the airspeed in cm/s as the wire carries it, or -1 for a state the codec refuses
        (the entries before it are then meaningless: ``HilRoundTrip`` raises its error).

    Returns
    -------
    int
        0: the metrics' tail ring is full and nothing was done (``add_step`` grows it, then
        fly with ``Vehicle.step``). 1 or 2: the metrics' answer (2: crashed), the vehicle
        flown and ``nav_next`` written. 5 or 6: the same metrics' answer, but the commands
        were not finite: the vehicle and ``nav_next`` untouched (``Vehicle.step`` raises).
    """
    # the arguments as views without reference counting for the callees (base.nrt: the
    # caller holds the arrays for the whole call)
    s = borrowed(s)
    tail = borrowed(tail)
    pos = borrowed(pos)
    ref = borrowed(ref)
    u = borrowed(u)
    ws = borrowed(ws)
    stuck = borrowed(stuck)
    buf = borrowed(buf)
    layout = borrowed(layout)
    home = borrowed(home)
    nav_next = borrowed(nav_next)
    r = metrics_step(s, tail, time_usec, pos, roll, pitch, yaw, mode, armed, ref, alt_ref,
                     airspeed)
    if r == 0:
        return 0
    if not take_and_step_packed(u, ws, stuck, n, dt, buf, layout, flags, True):
        return r + 4
    x, _u, _eff, _wind, fm, _memo = packed_views(ws, u.size)
    nav_next[13] = round_trip_kernel(x, fm[6], home[0], home[1], home[2], home[3], home[4],
                                      nav_next)
    return r
