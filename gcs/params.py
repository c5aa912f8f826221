"""Parameters of the ground station: the MAVLink parameter protocol as a client.

INT32 values travel bytewise in the float, as PX4 expects
(MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE, :mod:`vtolftc.protocols.px4`); the type of a
parameter is learnt from its PARAM_VALUE (read first if not seen yet).
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

from vtolftc.gcs.connection import GcsConnection, GcsError, GcsTimeout
from vtolftc.gcs.telemetry import param_id_of
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.px4 import decode_param_value, encode_param_value

__all__ = ["ParamClient", "param_id"]

PARAM_TYPE_INT32 = mav.MAV_PARAM_TYPE_INT32


def param_id(name: str) -> str:
    """``name`` checked as a MAVLink parameter id (1-16 ASCII characters)."""
    pid = str(name).strip()
    if not 0 < len(pid) <= 16 or not pid.isascii():
        raise GcsError(f"parameter name {name!r}: expected 1-16 ASCII characters")
    return pid


class ParamClient(GcsConnection):
    """The parameter side of a ground station (module docstring)."""

    def param_get(self, name: str, timeout_s: float = 1.0, retries: int = 2) -> float:
        """Value of parameter ``name`` (INT32 decoded from PX4's bytewise encoding)."""
        pid = param_id(name)
        msg = self.request(self.codec.param_request_read_encode(*self.target, pid.encode(), -1),
                           lambda m: m.get_type() == "PARAM_VALUE" and param_id_of(m) == pid,
                           timeout_s, retries)
        if msg is None:
            raise GcsTimeout(f"no PARAM_VALUE for {pid} within {timeout_s:g} s: unknown "
                             "parameter or autopilot not answering")
        return decode_param_value(msg.param_value, msg.param_type)

    def param_set(self, name: str, value: float, timeout_s: float = 1.0,
                  retries: int = 2) -> float:
        """Set ``name``; returns the value the autopilot echoed (raises GcsError if it kept a
        different value, e.g. out of range)."""
        pid = param_id(name)
        ptype = self.cache.param_types.get(pid)
        if ptype is None:
            self.param_get(pid, timeout_s, retries)
            ptype = self.cache.param_types[pid]
        v = float(value)
        if not math.isfinite(v):
            raise GcsError(f"{pid} = {value!r}: expected a finite number")
        if ptype == PARAM_TYPE_INT32 and v != int(v):
            raise GcsError(f"{pid} is an integer parameter: {value!r} is not an integer")
        wire = encode_param_value(v, ptype)
        msg = self.request(
            self.codec.param_set_encode(self.target[0], self.target[1], pid.encode(), wire,
                                        ptype),
            lambda m: m.get_type() == "PARAM_VALUE" and param_id_of(m) == pid,
            timeout_s, retries)
        if msg is None:
            raise GcsTimeout(f"no PARAM_VALUE echo for {pid} within {timeout_s:g} s "
                             f"({retries + 1} attempts)")
        echoed = decode_param_value(msg.param_value, msg.param_type)
        if echoed != v and not (ptype != PARAM_TYPE_INT32 and abs(echoed - v) <= 1e-6 * abs(v)):
            raise GcsError(f"{pid} = {v:g} refused: the autopilot kept {echoed:g}")
        return echoed

    def params(self, timeout_s: float = 5.0) -> dict[str, float]:
        """Every parameter (PARAM_REQUEST_LIST, then PARAM_REQUEST_READ of missing indices)."""
        got: dict[int, tuple[str, float]] = {}
        count = [-1]
        done = threading.Event()

        def on_msg(m: Any) -> None:
            if m.get_type() == "PARAM_VALUE" and self.from_target(m):
                count[0] = int(m.param_count)
                got[int(m.param_index)] = (param_id_of(m),
                                           decode_param_value(m.param_value, m.param_type))
                if len(got) >= count[0]:
                    done.set()

        self.add_listener(on_msg)
        try:
            self.send(self.codec.param_request_list_encode(*self.target))
            deadline = time.monotonic() + timeout_s
            while not done.wait(0.3):
                if time.monotonic() >= deadline:
                    raise GcsTimeout(f"parameter list incomplete after {timeout_s:g} s: got "
                                     f"{len(got)} of {max(count[0], 0)}")
                if count[0] > 0:  # ask for what is missing
                    for i in range(count[0]):
                        if i not in got:
                            self.send(self.codec.param_request_read_encode(
                                *self.target, b"", i))
        finally:
            self.remove_listener(on_msg)
        return {name: value for _, (name, value) in sorted(got.items())}
