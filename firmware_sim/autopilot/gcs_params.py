"""Parameter service of the ground-station endpoint (PX4: ``mavlink_parameters``).

:class:`ParameterService` answers the MAVLink parameter protocol on the autopilot's
:class:`~vtolftc.firmware_sim.autopilot.interface.ParameterStore` for
:class:`~vtolftc.firmware_sim.autopilot.gcs_endpoint.GcsEndpoint`:

- PARAM_REQUEST_LIST: one PARAM_VALUE per parameter on the link it came from;
- PARAM_REQUEST_READ by name or index (``param_index`` >= 0 wins); an unknown name gets no
  answer (as the protocol says);
- PARAM_SET: an unknown name is refused with a STATUSTEXT; an invalid value (not finite, not
  an integer for INT32, outside the range) is refused in the worker (STATUSTEXT and the
  PARAM_VALUE of the value kept, on that link: the control thread never sees it); a valid one
  is applied by the control thread and echoed as PARAM_VALUE on every link, as PX4 does.

INT32 values travel bytewise in the float (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
:mod:`vtolftc.protocols.px4`). Addressed to system 1 or broadcast (0).
"""

from __future__ import annotations

import math
from typing import Any

from vtolftc.firmware_sim.autopilot.gcs_link import Handler
from vtolftc.firmware_sim.autopilot.interface import ParamError, ParamType
from vtolftc.protocols.generated import constants as mav
from vtolftc.protocols.link import Link
from vtolftc.protocols.px4 import decode_param_value, encode_param_value

__all__ = ["ParameterService", "param_problem", "text_of"]

SEVERITY_WARNING = mav.MAV_SEVERITY_WARNING


def text_of(s: Any) -> str:
    """A MAVLink char array (bytes or str, NUL padded) as a str."""
    if isinstance(s, bytes | bytearray):
        s = s.decode(errors="replace")
    return str(s).rstrip("\x00")


def param_problem(prm: Any, value: float) -> str:
    """Why ``value`` cannot be set on ``prm`` ("" if it can): the checks of
    :meth:`ParameterStore.set`, made in the worker so that invalid requests cost the control
    thread nothing."""
    if not math.isfinite(value):
        return f"{prm.name} = {value!r}: expected a finite number"
    if prm.type == ParamType.INT32 and value != int(value):
        return f"{prm.name} = {value!r}: expected an integer"
    if not prm.minimum <= value <= prm.maximum:
        return f"{prm.name} = {value!r}: expected {prm.minimum:g} .. {prm.maximum:g}"
    return ""


class ParameterService:
    """The parameter protocol (module docstring) for ``endpoint``, the owning GcsEndpoint
    (its autopilot's ``params``, its links ``io``, ``submit``, ``reply`` and ``on_event``)."""

    HANDLES = ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET")
    """Message types handled here (in the endpoint's worker thread)."""

    def __init__(self, endpoint: Any) -> None:
        self.ep = endpoint

    def handlers(self) -> dict[str, Handler]:
        """Handler of each message type of :attr:`HANDLES` (``f(link_index, link, msg)``)."""
        return {"PARAM_REQUEST_LIST": self.on_request_list,
                "PARAM_REQUEST_READ": self.on_request_read, "PARAM_SET": self.on_set}

    def param_value(self, index: int, link: Link | None) -> None:
        """Worker: PARAM_VALUE of parameter ``index`` on ``link`` (None: every link)."""
        store = self.ep.ap.params
        io = self.ep.io
        prm = store.by_index(index)
        codec = (link or io.links[0]).codec
        msg = codec.param_value_encode(prm.name.encode(), encode_param_value(prm.value, prm.type),
                                       int(prm.type), len(store), index)
        io.send(msg, link)

    def on_request_list(self, index: int, link: Link, msg: Any) -> None:
        """PARAM_REQUEST_LIST: every parameter on ``link``."""
        if msg.target_system in (0, 1):
            for i in range(len(self.ep.ap.params)):
                self.param_value(i, link)

    def on_request_read(self, index: int, link: Link, msg: Any) -> None:
        """PARAM_REQUEST_READ by index (>= 0) or name; unknown: no answer."""
        if msg.target_system not in (0, 1):
            return
        store = self.ep.ap.params
        try:
            i = int(msg.param_index) if msg.param_index >= 0 \
                else store.index(text_of(msg.param_id))
            self.param_value(i, link)
        except ParamError:
            return  # unknown parameter: no answer (MAVLink parameter protocol)

    def on_set(self, index: int, link: Link, msg: Any) -> None:
        """PARAM_SET: checked here, applied by the control thread, echoed on every link."""
        if msg.target_system not in (0, 1):
            return
        ep = self.ep
        store = ep.ap.params
        name = text_of(msg.param_id)
        if name not in store:
            ep.io.statustext(f"unknown parameter {name}", SEVERITY_WARNING, link)
            return
        pindex = store.index(name)
        prm = store.by_index(pindex)
        value = decode_param_value(msg.param_value, prm.type)
        problem = param_problem(prm, value)
        if problem:  # refused here: the control thread never sees it
            ep.io.statustext(problem, SEVERITY_WARNING, link)
            self.param_value(pindex, link)
            return

        def apply() -> None:  # control thread
            error = ""
            try:
                store.set(name, value)
                ep.on_event("param", f"{name} = {value:g}")
            except ParamError as exc:
                error = str(exc)

            def answer() -> None:
                if error:
                    ep.io.statustext(error, SEVERITY_WARNING, link)
                self.param_value(pindex, None)  # echo on every link, as PX4 does

            ep.reply(answer)

        ep.submit(index, msg, apply, lambda: self.param_value(pindex, link))
