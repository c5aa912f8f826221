"""PX4 conventions on the wire: custom-mode layout, mode names, INT32 parameter encoding.

PX4 packs its flight mode into HEARTBEAT.custom_mode as ``main << 16 | sub << 24`` (the
lower 16 bits are zero) and sets ``MAV_MODE_FLAG_CUSTOM_MODE_ENABLED`` in base_mode; the
armed state is ``MAV_MODE_FLAG_SAFETY_ARMED`` (128) of base_mode. PX4 parameters of type
INT32 travel in PARAM_VALUE / PARAM_SET's float field *bytewise* (the four bytes of the int32
reinterpreted as a float32, MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE), not converted.

No flight logic here: only the numbering that ground stations expect.
"""

from __future__ import annotations

import struct

from vtolftc.protocols.generated import constants as mav

__all__ = [
    "MAV_MODE_FLAG_CUSTOM_MODE_ENABLED",
    "MAV_MODE_FLAG_SAFETY_ARMED",
    "PX4_AUTO_SUB",
    "PX4_MAIN",
    "custom_mode",
    "decode_param_value",
    "encode_param_value",
    "mode_from_name",
    "mode_name",
]

MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
MAV_MODE_FLAG_SAFETY_ARMED = mav.MAV_MODE_FLAG_SAFETY_ARMED

PX4_MAIN: dict[str, int] = {
    "MANUAL": 1, "ALTCTL": 2, "POSCTL": 3, "AUTO": 4, "ACRO": 5, "OFFBOARD": 6,
    "STABILIZED": 7, "RATTITUDE": 8,
}
"""PX4_CUSTOM_MAIN_MODE values."""

PX4_AUTO_SUB: dict[str, int] = {
    "READY": 1, "TAKEOFF": 2, "LOITER": 3, "MISSION": 4, "RTL": 5, "LAND": 6,
    "FOLLOW_TARGET": 8, "PRECLAND": 9,
}
"""PX4_CUSTOM_SUB_MODE_AUTO values (sub modes of main mode AUTO)."""

_MAIN_BY_VALUE = {v: k for k, v in PX4_MAIN.items()}
_SUB_BY_VALUE = {v: k for k, v in PX4_AUTO_SUB.items()}

_PARAM_INT32 = 6  # MAV_PARAM_TYPE_INT32


def custom_mode(main: int, sub: int = 0) -> int:
    """HEARTBEAT.custom_mode of a PX4 (main, sub) mode."""
    return ((int(main) & 0xFF) << 16) | ((int(sub) & 0xFF) << 24)


def mode_name(custom: int) -> str:
    """``"AUTO.LOITER"``, ``"POSCTL"`` ... of a PX4 custom_mode (``"UNKNOWN(n)"`` otherwise)."""
    main = (int(custom) >> 16) & 0xFF
    sub = (int(custom) >> 24) & 0xFF
    name = _MAIN_BY_VALUE.get(main)
    if name is None:
        return f"UNKNOWN({int(custom)})"
    if name == "AUTO":
        return f"AUTO.{_SUB_BY_VALUE.get(sub, str(sub))}"
    return name


def mode_from_name(name: str) -> tuple[int, int]:
    """(main, sub) of a PX4 mode name such as ``"AUTO.LOITER"`` or ``"POSCTL"``.

    Raises
    ------
    ValueError
        unknown name (the message lists the known ones).
    """
    text = name.strip().upper()
    main_txt, _, sub_txt = text.partition(".")
    if main_txt in PX4_MAIN and not sub_txt and main_txt != "AUTO":
        return PX4_MAIN[main_txt], 0
    if main_txt == "AUTO" and sub_txt in PX4_AUTO_SUB:
        return PX4_MAIN["AUTO"], PX4_AUTO_SUB[sub_txt]
    known = [m for m in PX4_MAIN if m != "AUTO"] + [f"AUTO.{s}" for s in PX4_AUTO_SUB]
    raise ValueError(f"unknown PX4 mode {name!r}: expected one of {', '.join(known)}")


def encode_param_value(value: float, param_type: int) -> float:
    """The float that carries ``value`` in PARAM_VALUE / PARAM_SET (INT32: bytewise)."""
    if int(param_type) == _PARAM_INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_param_value(wire: float, param_type: int) -> float:
    """Inverse of :func:`encode_param_value` (INT32 values come back as exact integers)."""
    if int(param_type) == _PARAM_INT32:
        return float(struct.unpack("<i", struct.pack("<f", wire))[0])
    return float(wire)
