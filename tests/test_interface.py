"""The autopilot boundary: HIL_STATE_QUATERNION wire form, command rounding, parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.interface import (
    HilState,
    NavState,
    ParamError,
    ParameterStore,
    ParamType,
    decode_hil_state,
    encode_hil_state,
    wire_commands,
)
from vtolftc.protocols.hil import HilRoundTrip, HilStateDecoder, HilStateEncoder
from vtolftc.protocols.mavlink import make_codec

HOME = (45.5027, 9.1566, 120.0)


def _nav(rng: np.random.Generator) -> NavState:
    q = rng.normal(size=4)
    return NavState(int(rng.integers(0, 10**9)), q / np.linalg.norm(q), rng.normal(size=3),
                    rng.normal(scale=200.0, size=3), rng.normal(scale=10.0, size=3),
                    float(rng.uniform(0, 30)))


def test_round_trip_within_wire_resolution():
    rng = np.random.default_rng(1)
    for _ in range(200):
        nav = _nav(rng)
        back = decode_hil_state(encode_hil_state(nav, *HOME), *HOME)
        assert back.time_usec == nav.time_usec
        assert np.allclose(back.pos_ned_m, nav.pos_ned_m, atol=0.01)      # degE7 ~ 1.1 cm, mm
        assert np.allclose(back.vel_ned_m_s, nav.vel_ned_m_s, atol=0.005)  # cm/s, rounded
        assert np.allclose(back.q_wxyz, nav.q_wxyz, atol=1e-7)
        assert np.allclose(back.omega_body_rad_s, nav.omega_body_rad_s, rtol=1e-7)
        assert abs(back.airspeed_m_s - nav.airspeed_m_s) <= 0.005


def test_encoding_is_what_pymavlink_puts_on_the_wire():
    """Independent check: pack the fields with the generated MAVLink codec, parse the bytes
    back, and compare with the encoder's own rounding (float32, int ranges)."""
    rng = np.random.default_rng(2)
    codec = make_codec(system_id=1, component_id=1)
    for _ in range(50):
        h = encode_hil_state(_nav(rng), *HOME)
        msg = codec.hil_state_quaternion_encode(
            h.time_usec, list(h.attitude_quaternion), h.rollspeed, h.pitchspeed, h.yawspeed,
            h.lat, h.lon, h.alt, h.vx, h.vy, h.vz, h.ind_airspeed, h.true_airspeed,
            h.xacc, h.yacc, h.zacc)
        parsed = codec.parse_char(bytearray(msg.pack(codec)))
        assert tuple(parsed.attitude_quaternion) == h.attitude_quaternion
        assert (parsed.rollspeed, parsed.pitchspeed, parsed.yawspeed) == (
            h.rollspeed, h.pitchspeed, h.yawspeed)
        wire = HilState(parsed.time_usec, tuple(parsed.attitude_quaternion), parsed.rollspeed,
                        parsed.pitchspeed, parsed.yawspeed, parsed.lat, parsed.lon, parsed.alt,
                        parsed.vx, parsed.vy, parsed.vz, parsed.ind_airspeed,
                        parsed.true_airspeed)
        a, b = decode_hil_state(wire, *HOME), decode_hil_state(h, *HOME)
        assert np.array_equal(a.pos_ned_m, b.pos_ned_m)
        assert np.array_equal(a.q_wxyz, b.q_wxyz)


def _bits(nav: NavState) -> tuple:
    return (nav.time_usec, nav.q_wxyz.tobytes(), nav.omega_body_rad_s.tobytes(),
            nav.pos_ned_m.tobytes(), nav.vel_ned_m_s.tobytes(),
            np.float64(nav.airspeed_m_s).tobytes())


@pytest.mark.parametrize("home", [HOME, (-33.9, 151.2, 3.0), (0.0, -179.9, -20.0)])
def test_fused_round_trip_equals_the_codec_pair_bit_for_bit(home):
    """HilRoundTrip (the in-process runner's) is decode(encode(.)) to the last bit, including
    rounding ties, clipped fields and states far from home."""
    rng = np.random.default_rng(3)
    rt = HilRoundTrip(*home)
    cases = []
    for _ in range(300):
        x = np.concatenate([rng.normal(scale=200.0, size=3), rng.normal(scale=10.0, size=3),
                            rng.normal(size=4), rng.normal(size=3), rng.normal(size=15)])
        x[6:10] /= np.linalg.norm(x[6:10])
        cases.append((int(rng.integers(0, 10**9)), x, float(rng.uniform(0, 30))))
    tie = np.zeros(13)
    tie[3:6] = (0.125, -0.375, 0.005)   # 100 v on a .5 tie (round half to even)
    tie[6] = 1.0
    cases.append((7, tie, 0.125))
    big = tie.copy()
    big[3:6] = (400.0, -400.0, 1e4)     # clipped int16 velocities
    big[0:3] = (3e7, -3e7, -1e7)        # clipped latitude/longitude/altitude
    cases.append((8, big, 900.0))
    cases.append((9, big, -5.0))
    for t, x, air in cases:
        ref = decode_hil_state(encode_hil_state(
            NavState(t, x[6:10], x[10:13], x[0:3], x[3:6], air), *home), *home)
        assert _bits(rt(t, x, air)) == _bits(ref)


def test_fused_round_trip_rejects_a_zero_quaternion():
    with pytest.raises(ValueError, match="quaternion"):
        HilRoundTrip(*HOME)(0, np.zeros(13), 0.0)


def test_out_of_range_values_are_clipped_not_wrapped():
    nav = NavState(0, np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3),
                   np.array([400.0, -400.0, 0.0]), 900.0)
    h = encode_hil_state(nav, *HOME)
    assert (h.vx, h.vy, h.ind_airspeed) == (32767, -32768, 65535)


def test_zero_quaternion_is_rejected():
    h = encode_hil_state(NavState(0, np.zeros(4), np.zeros(3), np.zeros(3), np.zeros(3), 0.0),
                         *HOME)
    with pytest.raises(ValueError, match="quaternion"):
        decode_hil_state(h, *HOME)


def test_wire_commands_are_float32():
    u = np.linspace(-1, 1, 15) + 1e-9
    w = wire_commands(u)
    assert w.shape == (15,)
    assert np.array_equal(w, u.astype(np.float32).astype(np.float64))


def test_parameter_store():
    ps = ParameterStore()
    ps.register("SYS_FAILURE_EN", 0, ParamType.INT32, 0, 1)
    ps.register("MIS_TAKEOFF_ALT", 30.0, minimum=1.0, maximum=500.0)
    assert ps.index("MIS_TAKEOFF_ALT") == 1 and ps.by_index(0).name == "SYS_FAILURE_EN"
    assert ps.set("SYS_FAILURE_EN", 1).value == 1
    bad = [("SYS_FAILURE_EN", 0.5, "integer"), ("SYS_FAILURE_EN", 2, r"0 \.\. 1"),
           ("MIS_TAKEOFF_ALT", math.nan, "finite"), ("NOPE", 1, "unknown")]
    for name, value, match in bad:
        with pytest.raises(ParamError, match=match):
            ps.set(name, value)
    with pytest.raises(ParamError, match="1-16"):
        ps.register("A_NAME_LONGER_THAN_16", 0)
    with pytest.raises(ParamError, match="twice"):
        ps.register("SYS_FAILURE_EN", 0)


def test_compiled_round_trip_equals_its_python_and_refuses_alike():
    """HilRoundTrip's compiled path gives the bits of its Python path on states quantised so
    that many fields round on a tie, and what the codec refuses (NaN position, a float32
    overflow, a zero quaternion) raises the Python path's error."""
    rng = np.random.default_rng(8)
    rt = HilRoundTrip(*HOME)
    for _ in range(2000):
        x = np.concatenate([rng.integers(-4000, 4000, 3) / 2000.0,
                            rng.integers(-4000, 4000, 3) / 200.0,
                            rng.normal(size=4), rng.normal(size=3), rng.normal(size=15)])
        x[6:10] /= np.linalg.norm(x[6:10])
        air = float(rng.integers(0, 6000)) / 200.0
        assert _bits(rt(5, x, air)) == _bits(rt._python(5, x, air))
    for bad, err in (((0, math.nan), ValueError), ((6, 1e39), OverflowError),
                     ((6, 0.0), ValueError), ((4, math.inf), OverflowError)):
        x = np.zeros(13)
        x[6] = 1.0
        x[bad[0]] = bad[1]
        with pytest.raises(err):
            rt(0, x, 0.0)
        with pytest.raises(err):
            rt._python(0, x, 0.0)


def _wire_msg(codec, h: HilState):
    """The HIL_STATE_QUATERNION message the autopilot parses from ``h``'s bytes."""
    return codec.parse_char(bytearray(codec.hil_state_quaternion_encode(
        h.time_usec, list(h.attitude_quaternion), h.rollspeed, h.pitchspeed, h.yawspeed,
        h.lat, h.lon, h.alt, h.vx, h.vy, h.vz, h.ind_airspeed, h.true_airspeed,
        h.xacc, h.yacc, h.zacc).pack(codec)))


@pytest.mark.parametrize("home", [HOME, (-33.9, 151.2, 3.0), (0.0, -179.9, -20.0)])
def test_sitl_decoder_equals_decode_hil_state_bit_for_bit(home):
    """HilStateDecoder (the SITL autopilot's, straight from the parsed message) gives
    decode_hil_state's NavState to the last bit, clipped fields and ties included."""
    rng = np.random.default_rng(4)
    codec = make_codec(system_id=1, component_id=1)
    dec = HilStateDecoder(*home)
    navs = [_nav(rng) for _ in range(200)]
    navs.append(NavState(5, np.array([1.0, 0, 0, 0]), np.zeros(3), np.array([3e7, -3e7, -1e7]),
                         np.array([400.0, -400.0, 0.125]), 900.0))
    for nav in navs:
        msg = _wire_msg(codec, encode_hil_state(nav, *home))
        wire = HilState(msg.time_usec, tuple(msg.attitude_quaternion), msg.rollspeed,
                        msg.pitchspeed, msg.yawspeed, msg.lat, msg.lon, msg.alt, msg.vx,
                        msg.vy, msg.vz, msg.ind_airspeed, msg.true_airspeed)
        assert _bits(dec(msg)) == _bits(decode_hil_state(wire, *home))


def test_sitl_decoder_hands_the_kernels_the_in_process_argument_types():
    """The SITL autopilot's NavState arrays have the numba types of the in-process runner's
    (float64, 1-D, C-contiguous, writable, right shapes): another type would make every
    compiled kernel type-check a second signature, or compile one in flight."""
    numba = pytest.importorskip("numba")
    codec = make_codec(system_id=1, component_id=1)
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.normal(size=6), [1.0, 0.0, 0.0, 0.0], rng.normal(size=3)])
    ref = HilRoundTrip(*HOME)(1000, x, 12.0)
    nav = HilStateDecoder(*HOME)(_wire_msg(codec, encode_hil_state(ref, *HOME)))
    for name, n in (("q_wxyz", 4), ("omega_body_rad_s", 3), ("pos_ned_m", 3),
                    ("vel_ned_m_s", 3)):
        a, b = getattr(nav, name), getattr(ref, name)
        assert a.shape == (n,) and a.dtype == np.float64 and a.flags.c_contiguous
        assert a.flags.writeable
        assert numba.typeof(a) == numba.typeof(b), name
    assert type(nav.airspeed_m_s) is float and type(nav.time_usec) is int


def test_sitl_decoder_rejects_a_zero_quaternion():
    codec = make_codec(system_id=1, component_id=1)
    h = encode_hil_state(NavState(0, np.zeros(4), np.zeros(3), np.zeros(3), np.zeros(3), 0.0),
                         *HOME)
    with pytest.raises(ValueError, match="quaternion"):
        HilStateDecoder(*HOME)(_wire_msg(codec, h))


def _hil_bits(h: HilState) -> tuple:
    """Every field of ``h``, floats by their bits and ints by type and value."""
    out = []
    for v in (h.time_usec, *h.attitude_quaternion, h.rollspeed, h.pitchspeed, h.yawspeed,
              h.lat, h.lon, h.alt, h.vx, h.vy, h.vz, h.ind_airspeed, h.true_airspeed, h.xacc,
              h.yacc, h.zacc):
        out.append((type(v), np.float64(v).tobytes() if type(v) is float else v))
    return tuple(out)


@pytest.mark.parametrize("home", [HOME, (-33.9, 151.2, 3.0), (0.0, -179.9, -20.0)])
def test_sitl_encoder_equals_encode_hil_state_bit_for_bit(home):
    """HilStateEncoder (the SITL vehicle's, compiled) gives encode_hil_state's fields to the
    last bit: rounding ties, clipped fields, states far from home, and the Python path's
    own result or error for what the wire refuses."""
    rng = np.random.default_rng(6)
    enc = HilStateEncoder(*home)
    cases = []
    for _ in range(300):
        x = np.concatenate([rng.normal(scale=200.0, size=3), rng.normal(scale=10.0, size=3),
                            rng.normal(size=4), rng.normal(size=3), rng.normal(size=15)])
        x[6:10] /= np.linalg.norm(x[6:10])
        cases.append((int(rng.integers(0, 10**9)), x, float(rng.uniform(0, 30))))
    tie = np.zeros(13)
    tie[3:6] = (0.125, -0.375, 0.005)   # 100 v on a .5 tie (round half to even)
    tie[6] = 1.0
    cases.append((7, tie, 0.125))
    big = tie.copy()
    big[3:6] = (400.0, -400.0, 1e4)     # clipped int16 velocities
    big[0:3] = (3e7, -3e7, -1e7)        # clipped latitude/longitude/altitude
    cases += [(8, big, 900.0), (9, big, -5.0)]
    nanq = tie.copy()
    nanq[7] = math.nan                  # packs as a float32 NaN: no error on the wire
    for t, x, air in cases:
        ref = encode_hil_state(NavState(t, x[6:10], x[10:13], x[0:3], x[3:6], air), *home)
        assert _hil_bits(enc(t, x, air)) == _hil_bits(ref)
    infw = tie.copy()
    infw[10] = math.inf                 # packs as a float32 inf: no error on the wire either
    for t, x, air in ((10, nanq, 1.0), (11, infw, 1.0)):
        ref = encode_hil_state(NavState(t, x[6:10], x[10:13], x[0:3], x[3:6], air), *home)
        assert _hil_bits(enc(t, x, air)) == _hil_bits(ref)
    for i, bad, err in ((10, 1e39, OverflowError), (0, math.nan, ValueError)):
        x = tie.copy()
        x[i] = bad                      # a rate float32 cannot carry / a position NaN
        with pytest.raises(err):
            encode_hil_state(NavState(0, x[6:10], x[10:13], x[0:3], x[3:6], 1.0), *home)
        with pytest.raises(err):
            enc(0, x, 1.0)
