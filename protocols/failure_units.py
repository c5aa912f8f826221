"""Actuator names <-> MAVLink failure units and instances (MAV_CMD_INJECT_FAILURE numbering).

PX4 numbers motors and servos from 1 in the order of the vehicle's outputs. For an airframe
with actuator order ``lift rotors, pushers, surfaces`` (``n_l`` lift rotors, ``n_p`` pushers;
DS-1: rotor_1a .. rotor_4b, pusher_left, pusher_right, aileron_left, aileron_right, elevator,
rudder_left, rudder_right, so n_l = 8, n_p = 2):

================================  ===========================  ====================
actuator                          unit                         instance
================================  ===========================  ====================
lift rotors in airframe order     FAILURE_UNIT_SYSTEM_MOTOR    1 .. n_l
pushers in airframe order         FAILURE_UNIT_SYSTEM_MOTOR    n_l + 1 .. n_l + n_p
surfaces in airframe order        FAILURE_UNIT_SYSTEM_SERVO    1 .. 5
================================  ===========================  ====================

Instance 0 means every instance of the unit. The vehicle process, the autopilot's
ground-station endpoint and the ground station (:mod:`vtolftc.gcs.actuators`) all build this table
from
the airframe's actuator names, so they agree by construction. Only a numbering convention:
no flight logic.
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "FAILURE_UNIT_MOTOR",
    "FAILURE_UNIT_SERVO",
    "GROUPS",
    "ActuatorTable",
]

FAILURE_UNIT_MOTOR = 101
FAILURE_UNIT_SERVO = 102

GROUPS: dict[str, tuple[str, ...]] = {
    "ailerons": ("aileron_left", "aileron_right"),
    "rudders": ("rudder_left", "rudder_right"),
    "surfaces": ("aileron_left", "aileron_right", "elevator", "rudder_left", "rudder_right"),
}
"""Group names accepted besides single actuators (plus ``lift_rotors``, ``pushers``,
``motors``, ``servos``, built from the airframe)."""


@dataclass(frozen=True)
class ActuatorTable:
    """Motors and servos of a vehicle in output order (names as in the airframe file)."""

    motors: tuple[str, ...]
    servos: tuple[str, ...]

    @classmethod
    def from_names(cls, actuator_names: Sequence[str]) -> ActuatorTable:
        """Motors = names starting with ``rotor_`` then ``pusher_`` (airframe order), servos =
        the rest, in airframe order."""
        rotors = tuple(n for n in actuator_names if n.startswith("rotor_"))
        pushers = tuple(n for n in actuator_names if n.startswith("pusher_"))
        servos = tuple(n for n in actuator_names if n not in rotors and n not in pushers)
        return cls(rotors + pushers, servos)

    def unit_instance(self, name: str) -> tuple[int, int]:
        """(unit, 1-based instance) of one actuator name."""
        if name in self.motors:
            return FAILURE_UNIT_MOTOR, self.motors.index(name) + 1
        if name in self.servos:
            return FAILURE_UNIT_SERVO, self.servos.index(name) + 1
        raise ValueError(self._unknown(name))

    def name_of(self, unit: int, instance: int) -> str:
        """Actuator name of (unit, 1-based instance)."""
        names = self.motors if unit == FAILURE_UNIT_MOTOR else (
            self.servos if unit == FAILURE_UNIT_SERVO else None)
        if names is None:
            raise ValueError(f"failure unit {unit}: expected {FAILURE_UNIT_MOTOR} (motor) or "
                             f"{FAILURE_UNIT_SERVO} (servo)")
        if not 1 <= instance <= len(names):
            raise ValueError(f"instance {instance} of unit {unit}: expected 1..{len(names)}")
        return names[instance - 1]

    def groups(self) -> dict[str, tuple[str, ...]]:
        """Named actuator groups (``lift_rotors``, ``pushers``, surfaces ...) -> actuator names."""
        g = dict(GROUPS)
        for group, prefix in (("ailerons", "aileron"), ("rudders", "rudder")):
            g[group] = tuple(n for n in self.servos if n.startswith(prefix))
        g["surfaces"] = self.servos
        g["lift_rotors"] = tuple(n for n in self.motors if n.startswith("rotor_"))
        g["pushers"] = tuple(n for n in self.motors if n.startswith("pusher_"))
        g["motors"] = self.motors
        g["servos"] = self.servos
        return g

    def expand(self, name: str) -> list[str]:
        """Actuator names of a single name or a group name."""
        groups = self.groups()
        if name in groups:
            return [n for n in groups[name] if n in self.motors or n in self.servos]
        if name in self.motors or name in self.servos:
            return [name]
        raise ValueError(self._unknown(name))

    def _unknown(self, name: str) -> str:
        choices = [*self.motors, *self.servos, *self.groups()]
        near = difflib.get_close_matches(name, choices, n=3)
        hint = f" (did you mean {' or '.join(near)}?)" if near else ""
        return (f"unknown actuator {name!r}{hint}; expected one of {', '.join(choices)}")
