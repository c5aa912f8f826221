"""Missions of the ground station: download of the vehicle's mission plan (the MAVLink
mission protocol as a client: MISSION_REQUEST_LIST -> MISSION_COUNT, MISSION_REQUEST_INT ->
MISSION_ITEM_INT per item, then MISSION_ACK)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from vtolftc.gcs.connection import GcsConnection, GcsTimeout
from vtolftc.protocols.generated import constants as mav

__all__ = ["MissionClient"]

MISSION = mav.MAV_MISSION_TYPE_MISSION


class MissionClient(GcsConnection):
    """The mission side of a ground station (module docstring)."""

    def download_mission(self, timeout_s: float = 2.0, retries: int = 3) -> list[Any]:
        """The vehicle's mission (MISSION_REQUEST_LIST, then MISSION_REQUEST_INT per item):
        the MISSION_ITEM_INT messages in order. Raises :class:`GcsTimeout` if an answer does
        not come after ``retries`` tries."""
        c = self.codec

        def ask(msg: Any, pred: Callable[[Any], bool]) -> Any:
            answer = self.request(msg, pred, timeout_s, retries)
            if answer is None:
                raise GcsTimeout(f"mission download: no answer to {msg.get_type()} within "
                                 f"{timeout_s:g} s")
            return answer

        cnt = ask(c.mission_request_list_encode(*self.target, MISSION),
                  lambda m: m.get_type() == "MISSION_COUNT" and m.mission_type == MISSION)
        items = []
        for seq in range(int(cnt.count)):
            items.append(ask(c.mission_request_int_encode(*self.target, seq, MISSION),
                             lambda m, s=seq: m.get_type() == "MISSION_ITEM_INT"
                             and m.seq == s))
        self.send(c.mission_ack_encode(*self.target, mav.MAV_MISSION_ACCEPTED, MISSION))
        return items
