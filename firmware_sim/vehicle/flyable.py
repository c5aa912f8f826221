"""Can an airframe fly the dual-system mission? The trim checks the loader cannot make.

The loader (:mod:`vtolftc.airframe.loader`, layer 0) refuses what it can see in the file alone:
malformed fields, more actuators than HIL carries, hover thrust-to-weight below 1.2, no yaw
authority in hover. Whether the aircraft trims through its transition needs the vehicle model,
so it is checked here, by :mod:`vtolftc.firmware_sim.vehicle.trim`:

- hover at rest (lift-rotor thrusts within 0..1 cancelling weight and moments);
- the rotor-assisted transition (pitch 0) at a third and two thirds of the stall speed and at
  the stall speed (lift rotors, pusher(s) and elevator within their limits);
- wing-borne level flight at the transition-end airspeed and at the cruise airspeed.

A failure is one :class:`~vtolftc.airframe.loader.AirframeError` naming the field the
failure points to and the trim that failed. Units SI; airspeeds in m/s.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from vtolftc.airframe.loader import DS1_PATH, Airframe, AirframeError, load_airframe
from vtolftc.firmware_sim.vehicle.trim import TrimError, trim_hover, trim_level_flight

__all__ = ["check_flyable", "load_flyable_airframe"]

_CHECKED: set[str] = set()


def _shipped_ds1_sha256() -> str:
    return hashlib.sha256(DS1_PATH.read_bytes()).hexdigest()


def check_flyable(af: Airframe) -> None:
    """Raise :class:`AirframeError` unless ``af`` trims in hover, transition and cruise.

    Parameters
    ----------
    af : Airframe
        A loaded airframe (its :attr:`~Airframe.airspeeds` give the transition end and cruise).

    Raises
    ------
    AirframeError
        One line: the file, the field the failure points to, and the trim that failed.
    """
    key = af.sha256 or ""
    if (key and key in _CHECKED) or key == _shipped_ds1_sha256():
        return  # checked already (the shipped DS-1 by tests/test_airframe_runtime.py)
    speeds = af.airspeeds
    stall = af.stall_speed_m_s() if speeds is None else speeds.stall_m_s
    end = stall if speeds is None else speeds.transition_end_m_s
    cruise = end if speeds is None else speeds.cruise_m_s

    def refuse(field: str, value: object, what: str, exc: Exception) -> AirframeError:
        return AirframeError(f"{af.source}: field '{field}' = {value!r}: expected an airframe "
                             f"that can {what} ({' '.join(str(exc).split())})")

    try:
        trim_hover(af)
    except TrimError as exc:
        raise refuse("lift_rotors.rotor", [r.name for r in af.lift_rotors],
                     "hover (the airframe cannot fly)", exc) from None
    for frac in (1.0 / 3.0, 2.0 / 3.0, 1.0):
        v = frac * stall
        try:
            trim_level_flight(af, v, pitch_rad=0.0)
        except TrimError as exc:
            raise refuse("pushers.max_thrust_N", af.pushers[0].max_thrust_N,
                         f"trim the rotor-assisted transition at {v:.1f} m/s "
                         "(the transition cannot trim)", exc) from None
    for field, v in (("airspeeds.transition_end_m_s", end), ("airspeeds.cruise_m_s", cruise)):
        try:
            trim_level_flight(af, v)
        except TrimError as exc:
            raise refuse(field, round(v, 2), f"fly wing-borne at {v:.1f} m/s "
                         "(the transition cannot end in trimmed flight)", exc) from None
    if key:
        _CHECKED.add(key)


def load_flyable_airframe(path: str | Path | None = None) -> Airframe:
    """:func:`~vtolftc.airframe.loader.load_airframe`, then :func:`check_flyable`.

    Parameters
    ----------
    path : str or Path, optional
        The airframe TOML file (default: the shipped DS-1).

    Returns
    -------
    Airframe
        The loaded airframe, known to trim in hover, transition and cruise.

    Raises
    ------
    AirframeError
        A malformed or unflyable file (one line naming the field and the reason).
    """
    af = load_airframe(path)
    check_flyable(af)
    return af
