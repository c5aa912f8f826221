"""The mission microservice state machine, driven message by message as a pymavlink ground
station would (MAVLink mission protocol: upload, download, clear, set current, plan types,
refusals with the right MAV_MISSION_RESULT and nothing half-stored)."""

from __future__ import annotations

import math

import pytest

from vtolftc.firmware_sim.autopilot.mission import (
    FENCE,
    MAX_ITEMS,
    MISSION,
    RALLY,
    MissionItem,
    MissionProtocol,
    MissionStore,
    Result,
)
from vtolftc.protocols.mavlink import make_codec
from vtolftc.runners.mission_run import rectangle_mission

GCS = (255, 190)


@pytest.fixture
def proto():
    store = MissionStore()
    ap_codec = make_codec(system_id=1, component_id=1)
    return MissionProtocol(store, ap_codec), store


class Client:
    """The ground-station side: builds messages as they arrive at the autopilot."""

    def __init__(self, proto: MissionProtocol) -> None:
        self.proto = proto
        self.codec = make_codec(system_id=GCS[0], component_id=GCS[1])
        self.now = 0.0

    def send(self, msg):
        # through the wire: pack, then parse as the autopilot would receive it
        data = msg.pack(self.codec)
        parsed = self.proto.codec.parse_buffer(data)
        assert parsed and len(parsed) == 1
        return self.proto.handle(parsed[0], self.now)

    def item_msg(self, it: MissionItem, plan: int = MISSION):
        return self.codec.mission_item_int_encode(1, 1, it.seq, it.frame, it.command, 0,
                                                  it.autocontinue, it.param1, it.param2,
                                                  it.param3, it.param4, it.x, it.y, it.z, plan)

    def upload(self, items, plan=MISSION, count=None):
        """Answer every request; returns the final MISSION_ACK (or the last reply)."""
        replies = self.send(self.codec.mission_count_encode(1, 1, count or len(items), plan))
        while True:
            assert len(replies) == 1
            r = replies[0]
            if r.get_type() == "MISSION_ACK":
                return r
            assert r.get_type() == "MISSION_REQUEST_INT" and r.mission_type == plan
            assert (r.target_system, r.target_component) == GCS
            replies = self.send(self.item_msg(items[r.seq], plan))

    def download(self, plan=MISSION, as_int=True):
        (cnt,) = self.send(self.codec.mission_request_list_encode(1, 1, plan))
        assert cnt.get_type() == "MISSION_COUNT" and cnt.mission_type == plan
        out = []
        for seq in range(cnt.count):
            req = (self.codec.mission_request_int_encode if as_int
                   else self.codec.mission_request_encode)(1, 1, seq, plan)
            (m,) = self.send(req)
            assert m.get_type() == ("MISSION_ITEM_INT" if as_int else "MISSION_ITEM")
            out.append(MissionItem.from_msg(m))
        self.send(self.codec.mission_ack_encode(1, 1, 0, plan))
        return out


def test_upload_then_download_item_for_item(proto):
    p, store = proto
    c = Client(p)
    items = rectangle_mission()
    ack = c.upload(items)
    assert ack.type == Result.ACCEPTED and ack.mission_type == MISSION
    assert len(store.mission) == len(items)
    back = c.download()
    assert all(a.same_as(b) for a, b in zip(items, back, strict=True))
    # the legacy float form gives the same positions to within float32 degrees (~1 m)
    legacy = c.download(as_int=False)
    for a, b in zip(items, legacy, strict=True):
        assert a.command == b.command and abs(a.x - b.x) < 200 and abs(a.y - b.y) < 200


def test_bad_missions_are_refused_with_the_right_ack_and_nothing_is_half_stored(proto):
    p, store = proto
    c = Client(p)
    good = rectangle_mission()
    assert c.upload(good).type == Result.ACCEPTED
    before = list(store.mission)

    def with_item(k, **changes):
        items = list(good)
        d = dict(items[k].__dict__)
        d.update(changes)
        items[k] = MissionItem(**d)
        return items

    cases = [
        (with_item(3, command=31337), Result.UNSUPPORTED),            # unknown command
        (with_item(3, command=5001), Result.UNSUPPORTED),             # a fence item
        (with_item(3, x=int(91e7)), Result.INVALID_PARAM5_X),         # latitude > 90
        (with_item(4, y=int(-181e7)), Result.INVALID_PARAM6_Y),       # longitude < -180
        (with_item(4, z=math.inf), Result.INVALID_PARAM7),
        (with_item(2, frame=1), Result.UNSUPPORTED_FRAME),            # MAV_FRAME_LOCAL_NED
        (with_item(1, param1=7.0), Result.INVALID),                   # transition to state 7
    ]
    for items, result in cases:
        ack = c.upload(items)
        assert ack.type == result, (ack, result)
        assert store.mission == before  # the stored mission is untouched
    # too many items: refused at MISSION_COUNT already
    (ack,) = c.send(c.codec.mission_count_encode(1, 1, MAX_ITEMS[MISSION] + 1, MISSION))
    assert ack.type == Result.NO_SPACE
    assert store.mission == before
    # an item out of sequence ends the transfer with INVALID_SEQUENCE
    c.send(c.codec.mission_count_encode(1, 1, 3, MISSION))
    (ack,) = c.send(c.item_msg(good[2]))
    assert ack.type == Result.INVALID_SEQUENCE
    assert store.mission == before
    # a DO_JUMP to a missing item: the plan as a whole is invalid
    jump = MissionItem(len(good), 2, 177, 1, 99.0, 1.0, 0.0, 0.0, 0, 0, 0.0)
    assert c.upload([*good, jump]).type == Result.INVALID
    assert store.mission == before


def test_clear_set_current_and_mission_current(proto):
    p, store = proto
    c = Client(p)
    c.upload(rectangle_mission())
    (cur,) = c.send(c.codec.mission_set_current_encode(1, 1, 3))
    assert cur.get_type() == "MISSION_CURRENT" and cur.seq == 3 and store.current == 3
    assert cur.total == len(store.mission)
    (ack,) = c.send(c.codec.mission_set_current_encode(1, 1, 99))
    assert ack.get_type() == "MISSION_ACK" and ack.type == Result.ERROR and store.current == 3
    (ack,) = c.send(c.codec.mission_clear_all_encode(1, 1, MISSION))
    assert ack.type == Result.ACCEPTED and store.mission == []
    assert p.mission_current().mission_state == 1  # MISSION_STATE_NO_MISSION


def test_fence_and_rally_plans_and_unsupported_types(proto):
    p, store = proto
    c = Client(p)
    lat, lon = int(45.5e7), int(9.15e7)
    poly = [MissionItem(k, 5, 5001, 1, 4.0, 0.0, 0.0, 0.0, lat + dx, lon + dy, 0.0)
            for k, (dx, dy) in enumerate([(-5000, -5000), (5000, -5000), (5000, 5000),
                                          (-5000, 5000)])]
    assert c.upload(poly, FENCE).type == Result.ACCEPTED and len(store.plans[FENCE]) == 4
    assert c.upload(poly[:2], FENCE).type == Result.INVALID     # incomplete polygon
    assert len(store.plans[FENCE]) == 4
    rally = [MissionItem(0, 6, 5100, 1, 0.0, 0.0, 0.0, 0.0, lat, lon, 30.0, RALLY)]
    assert c.upload(rally, RALLY).type == Result.ACCEPTED and len(store.plans[RALLY]) == 1
    assert c.download(RALLY)[0].same_as(rally[0])
    # waypoints are not rally points; a mission item is not a fence vertex
    wp = [MissionItem(0, 6, 16, 1, 0.0, 0.0, 0.0, 0.0, lat, lon, 30.0)]
    assert c.upload(wp, RALLY).type == Result.UNSUPPORTED
    assert c.upload(wp, FENCE).type == Result.UNSUPPORTED
    # unknown plan type
    (ack,) = c.send(c.codec.mission_count_encode(1, 1, 1, 7))
    assert ack.type == Result.UNSUPPORTED and ack.mission_type == 7
    (ack,) = c.send(c.codec.mission_clear_all_encode(1, 1, 255))   # MAV_MISSION_TYPE_ALL
    assert ack.type == Result.ACCEPTED
    assert not any(store.plans.values())


def test_a_silent_partner_is_asked_again_then_given_up(proto):
    p, store = proto
    c = Client(p)
    items = rectangle_mission()
    c.send(c.codec.mission_count_encode(1, 1, len(items), MISSION))
    c.send(c.item_msg(items[0]))
    assert p.tick(c.now + 0.5) == []
    resent = []
    t = c.now
    for _ in range(5):
        t += 1.01
        (r,) = p.tick(t)
        resent.append((r.get_type(), r.seq))
    assert resent == [("MISSION_REQUEST_INT", 1)] * 5
    (ack,) = p.tick(t + 1.01)
    assert ack.get_type() == "MISSION_ACK" and ack.type == Result.OPERATION_CANCELLED
    assert store.mission == [] and p.upload is None
    # a duplicate of the last item (its request crossed our answer) gets the next request
    c.send(c.codec.mission_count_encode(1, 1, len(items), MISSION))
    c.send(c.item_msg(items[0]))
    (r,) = c.send(c.item_msg(items[0]))
    assert r.get_type() == "MISSION_REQUEST_INT" and r.seq == 1


def test_another_partner_cannot_interleave_an_upload(proto):
    p, _store = proto
    c = Client(p)
    other = Client(p)
    other.codec = make_codec(system_id=254, component_id=1)
    c.send(c.codec.mission_count_encode(1, 1, 3, MISSION))
    (ack,) = other.send(other.codec.mission_count_encode(1, 1, 2, MISSION))
    assert ack.type == Result.DENIED and (ack.target_system, ack.target_component) == (254, 1)
