"""Mission storage and the MAVLink mission microservice, as PX4 implements it.

Transport-independent: :meth:`MissionProtocol.handle` takes one received message and returns
the replies (pymavlink message objects built with the codec it was given); the caller sends
them back on the link the message came from. :meth:`MissionProtocol.tick` (wall clock)
resends an unanswered item request and gives up on a silent partner.

Three plans, as PX4 keeps them (``mission_type``): MISSION 0 (at most
:data:`MAX_ITEMS` [0] = 500 items), FENCE 1 (64 vertices / circles) and RALLY 2 (8 points).
``MAV_MISSION_TYPE_ALL`` (255) is only valid for MISSION_CLEAR_ALL.

Upload (MISSION_COUNT -> MISSION_REQUEST_INT seq 0..n-1 <- MISSION_ITEM_INT -> MISSION_ACK):
every item is checked when it arrives, the plan is checked as a whole after the last one, and
only then does it replace the stored plan (all or nothing). A refusal ends the transfer with
one MISSION_ACK saying why (MAV_MISSION_RESULT):

=========================== =============================================================
NO_SPACE (4)                MISSION_COUNT above the plan's capacity
UNSUPPORTED (3)             a command this autopilot does not fly, or a command of another
                            plan type (e.g. a fence vertex in a mission)
UNSUPPORTED_FRAME (2)       a navigation item in a frame other than global (AMSL or
                            relative to home), a command in a local frame
INVALID_PARAM5_X (10)       latitude outside [-90, 90] deg
INVALID_PARAM6_Y (11)       longitude outside [-180, 180] deg
INVALID_PARAM7 (12)         altitude not finite
INVALID_SEQUENCE (13)       an item with a seq that was not requested
INVALID (5)                 the plan as a whole is not flyable (DO_JUMP target out of range,
                            fence polygon with fewer than 3 vertices, ...)
DENIED (14)                 an upload while another partner's transfer is running
OPERATION_CANCELLED (15)    the transfer timed out (partner silent)
=========================== =============================================================

Download: MISSION_REQUEST_LIST -> MISSION_COUNT, then each MISSION_REQUEST_INT (or the legacy
MISSION_REQUEST, answered with a float MISSION_ITEM) is answered with the stored item,
``current`` = 1 on the current item; the client's MISSION_ACK ends it. MISSION_CLEAR_ALL
empties a plan (or all) and answers ACCEPTED. MISSION_SET_CURRENT (and the command
DO_SET_MISSION_CURRENT, see :meth:`MissionStore.set_current`) moves the current item and is
answered with MISSION_CURRENT (out of range: MISSION_ACK ERROR and a STATUSTEXT reason).

Item coordinates are kept exactly as they travel in MISSION_ITEM_INT (degE7 integers, altitude
float32 in metres), so a download returns item for item what was uploaded.
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from vtolftc.protocols.generated import constants as mav

__all__ = [
    "FENCE_COMMANDS",
    "MAX_ITEMS",
    "MISSION_COMMANDS",
    "MissionItem",
    "MissionProtocol",
    "MissionStore",
    "Result",
    "validate_plan",
]

# MAV_MISSION_TYPE
MISSION, FENCE = mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_FENCE
RALLY, ALL = mav.MAV_MISSION_TYPE_RALLY, mav.MAV_MISSION_TYPE_ALL
PLAN_NAMES = {MISSION: "mission", FENCE: "fence", RALLY: "rally"}
MAX_ITEMS = {MISSION: 500, FENCE: 64, RALLY: 8}
"""Capacity of each plan (PX4's dataman sizes)."""


class Result:
    """MAV_MISSION_RESULT values."""

    ACCEPTED = mav.MAV_MISSION_ACCEPTED
    ERROR = mav.MAV_MISSION_ERROR
    UNSUPPORTED_FRAME = mav.MAV_MISSION_UNSUPPORTED_FRAME
    UNSUPPORTED = mav.MAV_MISSION_UNSUPPORTED
    NO_SPACE = mav.MAV_MISSION_NO_SPACE
    INVALID = mav.MAV_MISSION_INVALID
    INVALID_PARAM5_X = mav.MAV_MISSION_INVALID_PARAM5_X
    INVALID_PARAM6_Y = mav.MAV_MISSION_INVALID_PARAM6_Y
    INVALID_PARAM7 = mav.MAV_MISSION_INVALID_PARAM7
    INVALID_SEQUENCE = mav.MAV_MISSION_INVALID_SEQUENCE
    DENIED = mav.MAV_MISSION_DENIED
    OPERATION_CANCELLED = mav.MAV_MISSION_OPERATION_CANCELLED


# MAV_FRAME
FRAME_GLOBAL, FRAME_MISSION = mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_MISSION
FRAME_GLOBAL_RELATIVE_ALT = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT
FRAME_GLOBAL_INT, FRAME_GLOBAL_RELATIVE_ALT_INT = (mav.MAV_FRAME_GLOBAL_INT,
                                                   mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
GLOBAL_FRAMES = frozenset({FRAME_GLOBAL, FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_INT,
                           FRAME_GLOBAL_RELATIVE_ALT_INT})
RELATIVE_FRAMES = frozenset({FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_RELATIVE_ALT_INT})

# MAV_CMD values of the items this autopilot flies (the navigator's modes, nav_*.py, fly them)
NAV_WAYPOINT = mav.MAV_CMD_NAV_WAYPOINT
NAV_LOITER_UNLIM = mav.MAV_CMD_NAV_LOITER_UNLIM
NAV_LOITER_TIME = mav.MAV_CMD_NAV_LOITER_TIME
NAV_RETURN_TO_LAUNCH = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
NAV_LAND, NAV_TAKEOFF = mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_NAV_TAKEOFF
NAV_VTOL_TAKEOFF, NAV_VTOL_LAND = mav.MAV_CMD_NAV_VTOL_TAKEOFF, mav.MAV_CMD_NAV_VTOL_LAND
NAV_DELAY = mav.MAV_CMD_NAV_DELAY
DO_JUMP, DO_CHANGE_SPEED = mav.MAV_CMD_DO_JUMP, mav.MAV_CMD_DO_CHANGE_SPEED
DO_LAND_START = mav.MAV_CMD_DO_LAND_START
DO_VTOL_TRANSITION = mav.MAV_CMD_DO_VTOL_TRANSITION
FENCE_POLYGON_INCLUSION = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
FENCE_POLYGON_EXCLUSION = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
FENCE_CIRCLE_INCLUSION = mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
FENCE_CIRCLE_EXCLUSION = mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
NAV_RALLY_POINT = mav.MAV_CMD_NAV_RALLY_POINT

NAV_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME, NAV_LAND,
                          NAV_TAKEOFF, NAV_VTOL_TAKEOFF, NAV_VTOL_LAND})
"""Items with a position (x, y, z are used)."""
MISSION_COMMANDS = NAV_COMMANDS | {NAV_RETURN_TO_LAUNCH, NAV_DELAY, DO_JUMP, DO_CHANGE_SPEED,
                                   DO_LAND_START, DO_VTOL_TRANSITION}
FENCE_COMMANDS = frozenset({FENCE_POLYGON_INCLUSION, FENCE_POLYGON_EXCLUSION,
                            FENCE_CIRCLE_INCLUSION, FENCE_CIRCLE_EXCLUSION})
ALLOWED = {MISSION: MISSION_COMMANDS, FENCE: FENCE_COMMANDS, RALLY: frozenset({NAV_RALLY_POINT})}

REQUEST_RETRY_S = 1.0
"""Resend an unanswered MISSION_REQUEST_INT after this long (wall clock)."""
REQUEST_RETRIES = 5
"""Give up the transfer after this many unanswered resends."""

_F32 = struct.Struct("<f")


def _f32(x: float) -> float:
    """``x`` rounded to float32 as the wire carries it (NaN kept)."""
    return _F32.unpack(_F32.pack(float(x)))[0]


@dataclass(frozen=True)
class MissionItem:
    """One stored plan item, in MISSION_ITEM_INT's own types.

    ``x``, ``y``: latitude and longitude in degE7 (integers; for items without a position the
    raw integer value of the field); ``z``: altitude [m] (AMSL in the global frames, above
    home in the relative ones); ``param1..4`` float32 as on the wire.
    """

    seq: int
    frame: int
    command: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int = MISSION

    @property
    def lat_deg(self) -> float:
        """Latitude (deg) from the item's ``x`` (degE7)."""
        return self.x * 1e-7

    @property
    def lon_deg(self) -> float:
        """Longitude (deg) from the item's ``y`` (degE7)."""
        return self.y * 1e-7

    @property
    def relative_alt(self) -> bool:
        """True when ``z`` is relative to home (a ..._RELATIVE_ALT frame)."""
        return self.frame in RELATIVE_FRAMES

    def altitude_amsl(self, home_alt_m: float) -> float:
        """Altitude above mean sea level [m] (relative frames add the home altitude)."""
        return self.z + home_alt_m if self.relative_alt else self.z

    def same_as(self, other: MissionItem) -> bool:
        """Field-for-field equality with NaN equal to NaN (as a round trip must give)."""
        a, b = self.__dict__, other.__dict__
        for k, v in a.items():
            w = b[k]
            if isinstance(v, float) and math.isnan(v):
                if not (isinstance(w, float) and math.isnan(w)):
                    return False
            elif v != w:
                return False
        return True

    @classmethod
    def from_msg(cls, msg: Any) -> MissionItem:
        """From a MISSION_ITEM_INT, or a legacy float MISSION_ITEM (degrees -> degE7)."""
        if msg.get_type() == "MISSION_ITEM_INT":
            x, y = int(msg.x), int(msg.y)
        else:
            x = _deg_e7(msg.x) if int(msg.command) in NAV_COMMANDS | {NAV_RALLY_POINT} \
                | FENCE_COMMANDS else round(msg.x) if math.isfinite(msg.x) else 0
            y = _deg_e7(msg.y) if int(msg.command) in NAV_COMMANDS | {NAV_RALLY_POINT} \
                | FENCE_COMMANDS else round(msg.y) if math.isfinite(msg.y) else 0
        return cls(int(msg.seq), int(msg.frame), int(msg.command), int(msg.autocontinue),
                   _f32(msg.param1), _f32(msg.param2), _f32(msg.param3), _f32(msg.param4),
                   x, y, _f32(msg.z), int(getattr(msg, "mission_type", MISSION)))


def _deg_e7(deg: float) -> int:
    if not math.isfinite(deg):
        return 2**31 - 1  # caught by the range check
    return round(deg * 1e7)


def check_item(item: MissionItem, plan: int) -> tuple[int, str]:
    """(MAV_MISSION_RESULT, reason) of one item on its own; ACCEPTED and "" if fine."""
    cmd = item.command
    if cmd not in ALLOWED[plan]:
        other = [PLAN_NAMES[p] for p, cmds in ALLOWED.items() if cmd in cmds]
        where = f" (a {other[0]} item)" if other else ""
        return Result.UNSUPPORTED, f"{PLAN_NAMES[plan]} item {item.seq}: command {cmd} " \
            f"not supported{where}"
    positional = cmd in NAV_COMMANDS or plan != MISSION
    if positional:
        if item.frame not in GLOBAL_FRAMES:
            return Result.UNSUPPORTED_FRAME, f"item {item.seq}: frame {item.frame} not " \
                "supported (use a global frame)"
        if not -90e7 <= item.x <= 90e7:
            return Result.INVALID_PARAM5_X, f"item {item.seq}: latitude {item.x * 1e-7:g} " \
                "outside [-90, 90] deg"
        if not -180e7 <= item.y <= 180e7:
            return Result.INVALID_PARAM6_Y, f"item {item.seq}: longitude {item.y * 1e-7:g} " \
                "outside [-180, 180] deg"
        if not math.isfinite(item.z) and plan != FENCE:
            return Result.INVALID_PARAM7, f"item {item.seq}: altitude not finite"
    elif item.frame not in GLOBAL_FRAMES | {FRAME_MISSION}:
        return Result.UNSUPPORTED_FRAME, f"item {item.seq}: frame {item.frame} not supported"
    if cmd == DO_VTOL_TRANSITION and item.param1 not in (3.0, 4.0):
        return Result.INVALID, f"item {item.seq}: DO_VTOL_TRANSITION state must be 3 or 4"
    if cmd == NAV_LOITER_TIME and not (math.isfinite(item.param1) and item.param1 >= 0):
        return Result.INVALID, f"item {item.seq}: loiter time must be >= 0 s"
    if cmd in (FENCE_CIRCLE_INCLUSION, FENCE_CIRCLE_EXCLUSION) and not item.param1 > 0:
        return Result.INVALID, f"item {item.seq}: fence circle radius must be > 0 m"
    return Result.ACCEPTED, ""


def validate_plan(items: list[MissionItem], plan: int) -> tuple[int, str]:
    """(MAV_MISSION_RESULT, reason) of a whole plan (each item and their combination)."""
    for k, it in enumerate(items):
        if it.seq != k:
            return Result.INVALID_SEQUENCE, f"item {k} has seq {it.seq}"
        res, why = check_item(it, plan)
        if res != Result.ACCEPTED:
            return res, why
    if plan == MISSION:
        for it in items:
            if it.command == DO_JUMP and not (0 <= it.param1 < len(items)
                                              and it.param1 != it.seq):
                return Result.INVALID, f"item {it.seq}: DO_JUMP target {it.param1:g} invalid"
    if plan == FENCE:
        k = 0
        while k < len(items):
            it = items[k]
            if it.command in (FENCE_POLYGON_INCLUSION, FENCE_POLYGON_EXCLUSION):
                n = int(it.param1)
                if n < 3 or k + n > len(items) or any(
                        items[j].command != it.command or int(items[j].param1) != n
                        for j in range(k, k + n)):
                    return Result.INVALID, f"fence item {k}: polygon of {n} vertices " \
                        "incomplete (need >= 3 of the same kind)"
                k += n
            else:
                k += 1
    return Result.ACCEPTED, ""


@dataclass
class MissionStore:
    """The three stored plans, the current mission item and what changed.

    ``on_change(plan)`` is called after a plan was replaced or cleared (the navigator restarts
    from the new current item); ``on_set_current(seq)`` after the current item moved.
    """

    plans: dict[int, list[MissionItem]] = field(
        default_factory=lambda: {MISSION: [], FENCE: [], RALLY: []})
    current: int = 0
    on_change: Callable[[int], None] | None = None
    on_set_current: Callable[[int], None] | None = None

    @property
    def mission(self) -> list[MissionItem]:
        """The items of the mission plan (MAV_MISSION_TYPE_MISSION)."""
        return self.plans[MISSION]

    def replace(self, plan: int, items: list[MissionItem]) -> tuple[int, str]:
        """Replace a plan by ``items`` if the whole plan is valid (else nothing changes)."""
        if len(items) > MAX_ITEMS[plan]:
            return Result.NO_SPACE, f"{PLAN_NAMES[plan]}: {len(items)} items, at most " \
                f"{MAX_ITEMS[plan]}"
        res, why = validate_plan(items, plan)
        if res != Result.ACCEPTED:
            return res, why
        self.plans[plan] = [replace(it, mission_type=plan) for it in items]
        if plan == MISSION:
            self.current = 0
        if self.on_change is not None:
            self.on_change(plan)
        return Result.ACCEPTED, ""

    def clear(self, plan: int) -> None:
        """Empty plan ``plan`` (``ALL``: all three); the mission's current item goes to 0."""
        for p in (MISSION, FENCE, RALLY) if plan == ALL else (plan,):
            self.plans[p] = []
            if p == MISSION:
                self.current = 0
            if self.on_change is not None:
                self.on_change(p)

    def set_current(self, seq: int) -> bool:
        """Make mission item ``seq`` current (False if out of range: nothing changes)."""
        if not 0 <= seq < len(self.mission):
            return False
        self.current = int(seq)
        if self.on_set_current is not None:
            self.on_set_current(self.current)
        return True


@dataclass
class _Upload:
    plan: int
    count: int
    partner: tuple[int, int]
    items: list[MissionItem] = field(default_factory=list)
    last_request_wall: float = 0.0
    retries: int = 0


class MissionProtocol:
    """The mission microservice on top of a :class:`MissionStore` (see the module docstring).

    Parameters
    ----------
    store
        the plans.
    codec
        a pymavlink ``MAVLink`` instance of the dialect (builds the replies).
    mission_state
        ``f() -> (mission_state, mission_mode)`` for MISSION_CURRENT
        (MISSION_STATE and MISSION_MODE enums; default NOT_STARTED / not in mission mode).
    on_text
        ``f(text)`` for refusal reasons (the endpoint sends them as STATUSTEXT).
    """

    MESSAGES = frozenset({"MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM",
                          "MISSION_REQUEST_LIST", "MISSION_REQUEST_INT", "MISSION_REQUEST",
                          "MISSION_ACK", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT"})
    """Message types :meth:`handle` takes."""

    def __init__(self, store: MissionStore, codec: Any, *,
                 mission_state: Callable[[], tuple[int, int]] | None = None,
                 on_text: Callable[[str], None] | None = None,
                 system_id: int = 1, component_id: int = 1) -> None:
        self.store = store
        self.codec = codec
        self.mission_state = mission_state or (lambda: (2, 0))
        self.on_text = on_text or (lambda text: None)
        self.ids = (system_id, component_id)
        self.upload: _Upload | None = None
        self.last_ack: tuple[int, int] | None = None
        """(result, plan) of the last MISSION_ACK this side sent."""

    # ------------------------------------------------------------------ helpers
    def _for_us(self, msg: Any) -> bool:
        return (getattr(msg, "target_system", 0) in (0, self.ids[0])
                and getattr(msg, "target_component", 0) in (0, self.ids[1]))

    def _ack(self, partner: tuple[int, int], result: int, plan: int, why: str = "") -> Any:
        self.last_ack = (result, plan)
        if why:
            self.on_text(why)
        return self.codec.mission_ack_encode(partner[0], partner[1], result, plan)

    def _request(self, up: _Upload, now: float) -> Any:
        up.last_request_wall = now
        return self.codec.mission_request_int_encode(up.partner[0], up.partner[1],
                                                     len(up.items), up.plan)

    def mission_current(self) -> Any:
        """MISSION_CURRENT now (seq, total, mission_state, mission_mode)."""
        n = len(self.store.mission)
        state, mode = self.mission_state()
        if n == 0:
            state = 1  # MISSION_STATE_NO_MISSION
        return self.codec.mission_current_encode(self.store.current if n else 0, n, state, mode)

    def item_msg(self, item: MissionItem, partner: tuple[int, int], as_int: bool) -> Any:
        """MISSION_ITEM_INT (``as_int``) or float MISSION_ITEM carrying ``item`` to ``partner``."""
        cur = int(item.mission_type == MISSION and item.seq == self.store.current)
        c = self.codec
        if as_int:
            return c.mission_item_int_encode(partner[0], partner[1], item.seq, item.frame,
                                             item.command, cur, item.autocontinue, item.param1,
                                             item.param2, item.param3, item.param4, item.x,
                                             item.y, item.z, item.mission_type)
        pos = item.command in NAV_COMMANDS | FENCE_COMMANDS | {NAV_RALLY_POINT}
        x = item.x * 1e-7 if pos else float(item.x)
        y = item.y * 1e-7 if pos else float(item.y)
        return c.mission_item_encode(partner[0], partner[1], item.seq, item.frame, item.command,
                                     cur, item.autocontinue, item.param1, item.param2,
                                     item.param3, item.param4, x, y, item.z, item.mission_type)

    # ------------------------------------------------------------------ entry points
    def handle(self, msg: Any, now: float | None = None) -> list[Any]:
        """Replies to one received mission message (empty if none is due)."""
        now = time.monotonic() if now is None else now
        t = msg.get_type()
        if t not in self.MESSAGES or not self._for_us(msg):
            return []
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        plan = int(getattr(msg, "mission_type", MISSION))
        if t == "MISSION_CLEAR_ALL":
            if plan not in (MISSION, FENCE, RALLY, ALL):
                return [self._ack(partner, Result.UNSUPPORTED, plan,
                                  f"mission type {plan} not supported")]
            self.store.clear(plan)
            self.upload = None
            return [self._ack(partner, Result.ACCEPTED, plan)]
        if t == "MISSION_SET_CURRENT":
            if self.store.set_current(int(msg.seq)):
                return [self.mission_current()]
            return [self._ack(partner, Result.ERROR, MISSION,
                              f"mission item {int(msg.seq)} does not exist "
                              f"({len(self.store.mission)} items)")]
        if plan not in (MISSION, FENCE, RALLY):
            return [self._ack(partner, Result.UNSUPPORTED, plan,
                              f"mission type {plan} not supported")]
        if t == "MISSION_COUNT":
            return self._on_count(msg, partner, plan, now)
        if t in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            return self._on_item(msg, partner, plan, now)
        if t == "MISSION_REQUEST_LIST":
            return [self.codec.mission_count_encode(partner[0], partner[1],
                                                    len(self.store.plans[plan]), plan)]
        if t in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            items = self.store.plans[plan]
            seq = int(msg.seq)
            if not 0 <= seq < len(items):
                return [self._ack(partner, Result.INVALID_SEQUENCE, plan,
                                  f"{PLAN_NAMES[plan]} item {seq} requested, have "
                                  f"{len(items)}")]
            return [self.item_msg(items[seq], partner, t == "MISSION_REQUEST_INT")]
        # MISSION_ACK from the partner: end of a download (nothing to answer)
        return []

    def _on_count(self, msg: Any, partner: tuple[int, int], plan: int,
                  now: float) -> list[Any]:
        up = self.upload
        if up is not None and up.partner != partner:
            return [self._ack(partner, Result.DENIED, plan,
                              "mission upload refused: another transfer is running")]
        count = int(msg.count)
        if count > MAX_ITEMS[plan]:
            self.upload = None
            return [self._ack(partner, Result.NO_SPACE, plan,
                              f"{PLAN_NAMES[plan]} of {count} items refused: at most "
                              f"{MAX_ITEMS[plan]}")]
        if count == 0:
            self.upload = None
            self.store.clear(plan)
            return [self._ack(partner, Result.ACCEPTED, plan)]
        self.upload = _Upload(plan, count, partner)
        return [self._request(self.upload, now)]

    def _on_item(self, msg: Any, partner: tuple[int, int], plan: int,
                 now: float) -> list[Any]:
        up = self.upload
        if up is None or up.partner != partner or up.plan != plan:
            # not uploading: PX4 answers a stray item with an error ACK
            return [self._ack(partner, Result.ERROR, plan)]
        seq = int(msg.seq)
        if seq == len(up.items) - 1:
            return [self._request(up, now)]  # a duplicate of the last one: ask for the next
        if seq != len(up.items):
            self.upload = None
            return [self._ack(partner, Result.INVALID_SEQUENCE, plan,
                              f"mission item {seq} received, {len(up.items)} expected")]
        item = replace(MissionItem.from_msg(msg), mission_type=plan)
        res, why = check_item(item, plan)
        if res != Result.ACCEPTED:
            self.upload = None
            return [self._ack(partner, res, plan, f"{PLAN_NAMES[plan]} refused: {why}")]
        up.items.append(item)
        up.retries = 0
        if len(up.items) < up.count:
            return [self._request(up, now)]
        self.upload = None
        res, why = self.store.replace(plan, up.items)
        if res != Result.ACCEPTED:
            why = f"{PLAN_NAMES[plan]} refused: {why}"
        return [self._ack(partner, res, plan, why)]

    def tick(self, now: float | None = None) -> list[Any]:
        """Wall-clock duties: resend an unanswered item request; cancel after the retries."""
        up = self.upload
        if up is None:
            return []
        now = time.monotonic() if now is None else now
        if now - up.last_request_wall < REQUEST_RETRY_S:
            return []
        if up.retries >= REQUEST_RETRIES:
            self.upload = None
            return [self._ack(up.partner, Result.OPERATION_CANCELLED, up.plan,
                              f"{PLAN_NAMES[up.plan]} upload timed out at item {len(up.items)}")]
        up.retries += 1
        return [self._request(up, now)]
