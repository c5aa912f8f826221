"""The references the autopilot's stages hand each other within and across control steps.

The mode logic (:mod:`.commander`) and the navigator set where to hold (altitude, horizontal
position, heading); the outer loops (:mod:`.outer_loops`) turn them into the attitude
reference and the force commands; the attitude stage adds the moments and the output stage
(:mod:`.output`) allocates the whole virtual command.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Setpoints"]


class Setpoints:
    """Mutable references shared by the autopilot's stages (one instance per autopilot).

    Attributes
    ----------
    alt_ref : float
        altitude reference above the NED origin [m, up].
    takeoff_alt : float
        takeoff altitude above the NED origin [m, up].
    hold_ne : ndarray, shape (2,)
        horizontal position held in the multicopter modes, NED north and east [m].
    hold_locked : bool
        ``hold_ne`` is held (else the position hold brakes first, then locks where stopped).
    yaw_hold : float
        heading reference [rad].
    ref : ndarray, shape (3,)
        attitude reference roll, pitch, yaw [rad] of the step.
    v : ndarray, shape (5,)
        virtual command ``[Fz, Fx, L, M, N]``: body FRD forces [N] and moments [N m].
    """

    __slots__ = ("alt_ref", "hold_locked", "hold_ne", "ref", "takeoff_alt", "v", "yaw_hold")

    def __init__(self) -> None:
        self.alt_ref = 0.0
        self.takeoff_alt = 30.0
        self.hold_ne = np.zeros(2)
        self.hold_locked = False
        self.yaw_hold = 0.0
        self.ref = np.zeros(3)
        self.v = np.zeros(5)
