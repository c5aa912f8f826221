"""The HIL step decoded from frame bytes (``RawFrame`` + :mod:`vtolftc.protocols.hil_frames`)
gives the very values of the message objects' path, and falls back on anything else."""

from __future__ import annotations

import functools
import math
import random
import struct
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from vtolftc.protocols.fastparse import FastParser, RawFrame
from vtolftc.protocols.hil import HilStateDecoder, NavState
from vtolftc.protocols.hil_frames import (
    HilStateFrameDecoder,
    actuator_controls,
    frame_time_usec,
)
from vtolftc.protocols.link import Link
from vtolftc.protocols.mavlink import SigningConfig, dialect, make_codec
from vtolftc.protocols.transport import LoopTransport

KEY = bytes(range(32))
HOMES = [(47.397742, 8.545594, 488.0), (-33.8688, 151.2093, 12.5), (0.0, -179.99, -30.0)]
_D = dialect()
ID_SENSOR = _D.MAVLink_hil_sensor_message.id
ID_STATE = _D.MAVLink_hil_state_quaternion_message.id
ID_CONTROLS = _D.MAVLink_hil_actuator_controls_message.id


def _bits(nav: NavState) -> tuple[Any, ...]:
    a = np.concatenate([nav.q_wxyz, nav.omega_body_rad_s, nav.pos_ned_m, nav.vel_ned_m_s])
    return (nav.time_usec, a.view(np.int64).tolist(),
            np.float64(nav.airspeed_m_s).view(np.int64).item())


def _f32(rng: random.Random) -> float:
    """A float32-representable value of any kind the wire can carry (zeros cut the payload
    short on the wire: the decoders must read the missing bytes as 0)."""
    kind = rng.random()
    if kind < 0.15:
        return 0.0
    if kind < 0.2:
        return rng.choice([1e-40, -1e-44, 3.4e38, -3.4e38])  # subnormal, near the maximum
    return rng.uniform(-2.0, 2.0) * 10.0 ** rng.randint(-6, 3)


def _random_state(rng: random.Random, t: int) -> Any:
    def i(lo: int, hi: int) -> int:
        return 0 if rng.random() < 0.15 else rng.randint(lo, hi)

    q = [_f32(rng) for _ in range(4)]
    return _D.MAVLink_hil_state_quaternion_message(
        t, q, _f32(rng), _f32(rng), _f32(rng), i(-2**31, 2**31 - 1), i(-2**31, 2**31 - 1),
        i(-2**31, 2**31 - 1), i(-32768, 32767), i(-32768, 32767), i(-32768, 32767),
        i(0, 65535), i(0, 65535), i(-32768, 32767), i(-32768, 32767), i(-32768, 32767))


def _raw(data: bytes, defer: tuple[int, ...], signing: SigningConfig | None = None) -> list[Any]:
    fast = FastParser(make_codec(1, 1, signing=signing), _D)
    fast.defer = frozenset(defer)
    got = fast.parse(data)
    assert got is not None
    return got


@pytest.mark.parametrize("home", HOMES)
def test_state_frames_decode_as_hil_state_decoder_bit_for_bit(home: tuple[float, ...]) -> None:
    """Random HIL_STATE_QUATERNION messages (any field zero, so payloads cut short; extreme
    integers; subnormal and huge floats; zero quaternions): the frame decoder's NavState
    equals :class:`HilStateDecoder`'s of the generated parser's message bit for bit, and a
    quaternion the reference refuses gives None."""
    rng = random.Random(3)
    tx = make_codec(1, 200)
    ref = HilStateDecoder(*home)
    dec = HilStateFrameDecoder(*home)
    refused = 0
    for k in range(3000):
        t = 0 if k % 50 == 0 else rng.randint(0, 2**64 - 1) if k % 7 == 0 else 4000 * k
        msg = _random_state(rng, t)
        if k % 40 == 0:
            msg.attitude_quaternion = [0.0, 0.0, 0.0, 0.0]
        if k % 97 == 0:
            msg.attitude_quaternion = [float("inf"), 0.0, 0.0, 0.0]
        data = msg.pack(tx)
        (raw,) = _raw(data, (ID_STATE,))
        assert type(raw) is RawFrame and raw.get_type() == "HIL_STATE_QUATERNION"
        assert frame_time_usec(raw) == t
        got = dec(raw)
        try:
            want = ref(raw.message())
        except ValueError:
            assert got is None, k
            refused += 1
            continue
        assert got is not None and _bits(got) == _bits(want), k
    assert refused >= 75


@pytest.mark.parametrize("signed", [False, True])
def test_deferred_frames_make_the_generated_parsers_messages(signed: bool) -> None:
    """Step datagrams (HIL_SENSOR + HIL_STATE_QUATERNION + a HEARTBEAT) through a link that
    defers the two HIL ids: ``RawFrame.message()`` is the generated parser's message,
    attribute by attribute (source address too), the other frames message objects, and the
    counters and signing state those of a link without deferral."""
    from test_protocols_fastparse import _hil_datagram, _state

    rx = [Link(LoopTransport(), system_id=1, component_id=1, track_source=True,
               signing=SigningConfig(KEY, timestamp=10) if signed else None) for _ in range(2)]
    rx[0].defer((ID_SENSOR, ID_STATE))
    for i in range(60):
        data = _hil_datagram(SigningConfig(KEY, timestamp=1000 + 10 * i) if signed else None,
                             4000 * (i + 1))
        got = []
        for link in rx:
            link.transport.send_bytes(data)
            got.append(link.recv(0))
        kinds = [type(m) is RawFrame for m in got[0]]
        assert kinds[:2] == [True, True] and not any(kinds[2:])
        assert [_state(m.message() if type(m) is RawFrame else m) for m in got[0]] \
            == [_state(m) for m in got[1]], i
        assert got[0][0].message() is got[0][0].message()
    assert rx[0].stats.as_dict() == rx[1].stats.as_dict()
    assert rx[0].codec.signing.timestamp == rx[1].codec.signing.timestamp


@functools.cache
def _flight(signed: bool, corrupt: bool) -> list[tuple[bytes, bytes]]:
    """A short flight's state datagrams (vehicle -> autopilot) and HIL_ACTUATOR_CONTROLS
    answers (autopilot -> vehicle), every fifth of each with a flipped byte if ``corrupt``."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
    from vtolftc.firmware_sim.vehicle.battery import BatteryModel
    from vtolftc.firmware_sim.vehicle.model import Vehicle
    from vtolftc.firmware_sim.vehicle.state_encoder import StateEncoder

    rng = random.Random(5)
    af = load_airframe()
    vehicle = Vehicle(af)
    codec = make_codec(1, 191, signing=SigningConfig(KEY, timestamp=1000) if signed else None)
    enc = StateEncoder(vehicle, BatteryModel(rho=af.air_density_kg_m3), codec, 10.0,
                       lambda: codec.heartbeat_encode(0, 0, 0, 0, 0))
    tx = LoopTransport()
    bridge = HilBridge(Link(tx, system_id=1, component_id=1,
                            signing=SigningConfig(KEY, timestamp=1000) if signed else None))
    u = np.linspace(0.2, 0.6, af.n_actuators)
    out = []
    for k in range(250):
        state = bytearray(enc.datagram())
        vehicle.step(u, 4)
        u[k % af.n_actuators] = 0.1 + 0.003 * k
        sent = u.copy()
        if k % 31 == 30:
            sent[k % af.n_actuators] = np.inf
        bridge.send_controls(vehicle.time_usec, sent, armed=k % 2 == 0)
        controls = bytearray(tx.queue.pop())
        if corrupt and k % 5 == 0:
            for data in (state, controls):
                data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        out.append((bytes(state), bytes(controls)))
        if k % 3 == 0:
            out.append((bytes(state), bytes(controls)))  # resent: an answer was lost
    return out


@pytest.mark.parametrize("signed", [False, True])
def test_bridge_steps_on_frames_as_on_messages(signed: bool) -> None:
    """A flight's state datagrams (some corrupted, some resent) into two ``HilBridge``s, one
    reading the step from the frames' bytes, one from message objects (deferral off): the
    same steps, NavState bit for bit, the same counters, and the same HIL_SENSOR /
    HIL_STATE_QUATERNION for the observers (ULog, ground-station streams)."""
    from test_protocols_fastparse import _state

    from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge

    sig = (lambda: SigningConfig(KEY, timestamp=10)) if signed else (lambda: None)
    bridges = [HilBridge(Link(LoopTransport(), system_id=1, component_id=1, signing=sig()))
               for _ in range(2)]
    bridges[1].link.defer(())
    steps = 0
    for state, _ in _flight(signed, corrupt=True):
        navs = []
        for b in bridges:
            b.link.transport.send_bytes(state)
            b.drain(0.0)
            navs.append(b.take())
            if navs[-1] is not None:
                b.send_controls(navs[-1].time_usec, np.zeros(3), armed=True)
        assert (navs[0] is None) == (navs[1] is None)
        if navs[0] is not None:
            assert _bits(navs[0]) == _bits(navs[1])
            steps += 1
        for attr in ("last_sensor", "last_state"):
            m = [getattr(b, attr) for b in bridges]
            assert (m[0] is None) == (m[1] is None)
            if m[0] is not None:
                assert _state(m[0]) == _state(m[1])
        for attr in ("decode_errors", "superseded", "resent", "steps_answered", "home"):
            assert getattr(bridges[0], attr) == getattr(bridges[1], attr), attr
    # signed, a datagram sent twice is a replay: dropped (the vehicle signs a resend anew)
    assert steps >= 180 and bridges[0].resent >= (0 if signed else 60)
    assert bridges[0].link.stats.as_dict() == bridges[1].link.stats.as_dict()


@pytest.mark.parametrize("signed", [False, True])
def test_vehicle_reads_controls_from_frames_as_from_messages(signed: bool) -> None:
    """A flight's HIL_ACTUATOR_CONTROLS (some corrupted, some with an infinite command) read
    by the vehicle's ``_controls`` from deferred frames and from message objects: the same
    time, mode, finiteness and controls, bit for bit, for every frame that got through."""
    from vtolftc.firmware_sim.vehicle.process import _controls

    sig = (lambda: SigningConfig(KEY, timestamp=10)) if signed else (lambda: None)
    links = [Link(LoopTransport(), system_id=1, component_id=1, signing=sig())
             for _ in range(2)]
    links[0].defer((ID_CONTROLS,))
    seen = infinite = 0
    for _, controls in _flight(signed, corrupt=True):
        got = []
        for link in links:
            link.transport.send_bytes(controls)
            got.append(link.recv(0))
        assert len(got[0]) == len(got[1])
        for a, b in zip(*got, strict=True):
            assert (type(a) is RawFrame) and type(b) is not RawFrame
            for n in (3, 16, 0):
                ta, ma, fa, ca = _controls(a, n)
                tb, mb, fb, cb = _controls(b, n)
                assert (ta, ma, fa) == (tb, mb, fb)
                assert np.asarray(ca).view(np.int64).tolist() \
                    == np.asarray(cb, dtype=np.float64).view(np.int64).tolist()
            seen += 1
            infinite += not _controls(a, 16)[2]
    assert seen >= 200 and infinite >= 3
    with pytest.raises(ValueError, match="16"):
        actuator_controls(a, 17)


def test_controls_frames_of_random_messages() -> None:
    """Random HIL_ACTUATOR_CONTROLS (zeros cut the payload short, NaN and infinities): the
    compiled read gives the message's fields."""
    rng = random.Random(9)
    tx = make_codec(1, 1)
    for k in range(1500):
        c = [_f32(rng) for _ in range(16)]
        if k % 11 == 0:
            c[rng.randrange(16)] = rng.choice([math.nan, math.inf, -math.inf])
        if k % 13 == 0:
            c = [0.0] * 16
        t = rng.choice([0, 4000 * k, 2**64 - 1])
        msg = _D.MAVLink_hil_actuator_controls_message(
            t, c, rng.choice([0, 128, 255]), rng.choice([0, 1, 2**64 - 1]))
        (raw,) = _raw(msg.pack(tx), (ID_CONTROLS,))
        m = raw.message()
        t_got, mode, finite, got = actuator_controls(raw, 16)
        assert (t_got, mode, finite) == (m.time_usec, m.mode,
                                         all(map(math.isfinite, m.controls)))
        assert got.view(np.int64).tolist() == np.array(m.controls).view(np.int64).tolist()
        assert frame_time_usec(raw) == m.time_usec


def _random_state_vector(rng: random.Random) -> np.ndarray:
    x = np.array([rng.uniform(-3e3, 3e3) for _ in range(3)]
                 + [rng.uniform(-400.0, 400.0) for _ in range(3)]
                 + [rng.uniform(-1.0, 1.0) for _ in range(4)]
                 + [rng.uniform(-5.0, 5.0) for _ in range(3)] + [0.0] * rng.randint(0, 4))
    k = rng.random()
    if k < 0.1:
        x[rng.randrange(13)] = 0.0
    elif k < 0.13:
        x[rng.randrange(13)] = rng.choice([np.nan, np.inf, 1e39, -1e300])
    elif k < 0.16:
        x[rng.randrange(6)] *= 1e6  # clipped to the integer fields' range
    return x


@pytest.mark.parametrize("signed", [False, True])
@pytest.mark.parametrize("home", HOMES[:2])
def test_compiled_packers_give_frame_packer_bytes(signed: bool, home: tuple[float, ...]) -> None:
    """Random sensor samples and states (zeros cut on the wire, NaN, infinities, float32
    overflow, clipped integers, sequence numbers wrapping): ``HilFramePackers`` gives the
    bytes of ``FramePacker.pack`` of the same values (HilStateEncoder's fields for the
    state), or declines exactly where the general path raises; signing state and sequence
    numbers advance alike."""
    from vtolftc.protocols.fastpack import FramePacker
    from vtolftc.protocols.hil import HilStateEncoder
    from vtolftc.protocols.hil_frames import HilFramePackers

    rng = random.Random(17)
    sig = (lambda: SigningConfig(KEY, link_id=2, timestamp=7)) if signed else (lambda: None)
    ca, cb = make_codec(1, 200, signing=sig()), make_codec(1, 200, signing=sig())
    fast = HilFramePackers(ca, *home)
    sensor = FramePacker(cb, _D.MAVLink_hil_sensor_message)
    state = FramePacker(cb, _D.MAVLink_hil_state_quaternion_message)
    enc = HilStateEncoder(*home)
    def general(packer: FramePacker, t: int, x: np.ndarray, air: float) -> bytes:
        hs = enc(t, x, air)
        return packer.pack(hs.time_usec, *hs.attitude_quaternion, hs.rollspeed,
                           hs.pitchspeed, hs.yawspeed, hs.lat, hs.lon, hs.alt, hs.vx, hs.vy,
                           hs.vz, hs.ind_airspeed, hs.true_airspeed, hs.xacc, hs.yacc,
                           hs.zacc)

    declined = compiled = 0
    for k in range(1500):
        t = rng.choice([0, 4000 * k, 2**62])
        air = rng.choice([0.0, rng.uniform(0.0, 40.0), 1e6, -3.0])
        x = _random_state_vector(rng)
        got = fast.state_frame(t, x, air)
        try:
            want = general(state, t, x, air)
        except (ValueError, OverflowError):
            assert got is None, k  # declined where the general path raises
            declined += 1
            continue
        if got is None:  # declined (a NaN in the quaternion): the caller's general path
            got = general(fast.state, t, x, air)
        else:
            compiled += 1
        assert got == want, k
        vals = [_f32(rng) if rng.random() < 0.9 else rng.choice([np.nan, np.inf, 1e39])
                for _ in range(13)]
        arrays = [np.array(vals[i:i + 3]) for i in (0, 3, 6)]
        fields, sid = rng.choice([0, 0x1FFF, 2**32 - 1]), rng.choice([0, 1, 255])
        got = fast.sensor_frame(t, *arrays, *vals[9:], fields, sid)
        try:
            want = sensor.pack(t, *vals, fields, sid)
        except (struct.error, OverflowError):
            assert got is None, k
            declined += 1
            continue
        assert got == want, k
        compiled += 1
    assert declined >= 60 and compiled >= 2000
    assert (ca.seq, ca.signing.timestamp) == (cb.seq, cb.signing.timestamp)


@pytest.mark.parametrize("signed", [False, True])
def test_state_encoder_datagrams_unchanged_by_the_compiled_packers(signed: bool) -> None:
    """A short flight's state datagrams (and their resends) from a ``StateEncoder`` whose
    compiled packers decline everything (the general path) and from one that uses them:
    the same bytes."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.vehicle.battery import BatteryModel
    from vtolftc.firmware_sim.vehicle.model import Vehicle
    from vtolftc.firmware_sim.vehicle.state_encoder import StateEncoder

    af = load_airframe()
    encs, vehicles = [], []
    for fast in (True, False):
        v = Vehicle(af)
        codec = make_codec(1, 191,
                           signing=SigningConfig(KEY, timestamp=50) if signed else None)
        enc = StateEncoder(v, BatteryModel(rho=af.air_density_kg_m3), codec, 10.0,
                           lambda c=codec: c.heartbeat_encode(0, 0, 0, 0, 0), resign=signed)
        if not fast:
            enc._packers = SimpleNamespace(  # type: ignore[assignment]
                sensor_frame=lambda *a: None, state_frame=lambda *a: None)
        encs.append(enc)
        vehicles.append(v)
    u = np.linspace(0.2, 0.7, af.n_actuators)
    for k in range(300):
        grams = [e.datagram() for e in encs]
        assert grams[0] == grams[1], k
        packers = encs[0]._packers
        assert [p for p, _ in encs[0]._parts if p in (packers.sensor_frame,
                                                       packers.state_frame)] \
            == [packers.sensor_frame, packers.state_frame]  # the compiled path flew
        for v in vehicles:
            v.step(u, 4)
        if k % 7 == 0:  # the last datagram's messages, even after the state moved on
            assert encs[0].again(grams[0]) == encs[1].again(grams[1]), k
