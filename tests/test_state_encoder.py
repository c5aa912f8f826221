"""The vehicle's state datagram: the generated encoding's bytes, message for message."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.vehicle.battery import BatteryModel
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.state_encoder import FIELDS_ALL, StateEncoder
from vtolftc.protocols.hil import encode_hil_state
from vtolftc.protocols.mavlink import SigningConfig, make_codec


def _reference(v: Vehicle, codec: Any, with_gps: bool, with_origin: bool) -> bytes:
    """HIL_SENSOR [+ HIL_GPS] + HIL_STATE_QUATERNION with the generated encoders (the
    encoder's occasional messages excluded: origin first, if any, is added by the caller)."""
    def pack(msg: Any) -> bytes:
        data = msg.pack(codec)
        codec.seq = (codec.seq + 1) & 0xFF
        return data

    t = v.time_usec
    s = v.sensors()
    out = b""
    if with_origin:
        h = v.sensor_model.home
        out += pack(codec.gps_global_origin_encode(round(h.lat_deg * 1e7),
                                                   round(h.lon_deg * 1e7),
                                                   round(h.alt_m * 1e3), t))
    a, g, m = s.accel_m_s2, s.gyro_rad_s, s.mag_gauss
    out += pack(codec.hil_sensor_encode(t, a[0], a[1], a[2], g[0], g[1], g[2], m[0], m[1],
                                        m[2], s.abs_pressure_hpa, s.diff_pressure_hpa,
                                        s.pressure_alt_m, s.temperature_c, FIELDS_ALL, 0))
    if with_gps:
        vn, ve, vd = (float(x) for x in s.gps_vel_ned_m_s)
        cog = round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100) % 36000
        out += pack(codec.hil_gps_encode(
            t, 3, round(s.gps_lat_deg * 1e7), round(s.gps_lon_deg * 1e7),
            round(s.gps_alt_m * 1e3), 100, 100, min(65535, round(100 * math.hypot(vn, ve))),
            round(100 * vn), round(100 * ve), round(100 * vd), cog, 12, 0, 0))
    from vtolftc.protocols.hil import NavState

    x = v.x
    h = v.sensor_model.home
    hs = encode_hil_state(NavState(t, x[6:10], x[10:13], x[0:3], x[3:6], float(v.fm[6])),
                          h.lat_deg, h.lon_deg, h.alt_m)
    out += pack(codec.hil_state_quaternion_encode(
        hs.time_usec, hs.attitude_quaternion, hs.rollspeed, hs.pitchspeed, hs.yawspeed,
        hs.lat, hs.lon, hs.alt, hs.vx, hs.vy, hs.vz, hs.ind_airspeed, hs.true_airspeed,
        hs.xacc, hs.yacc, hs.zacc))
    return out


@pytest.mark.parametrize("signed", [False, True])
def test_datagrams_equal_generated_encoding(signed: bool) -> None:
    af = load_airframe()
    v = Vehicle(af)
    signing = SigningConfig(secret_key=bytes(range(32)), timestamp=10**9) if signed else None
    codec, ref = make_codec(1, 191, signing=signing), make_codec(1, 191, signing=signing)
    status = []  # the 1 Hz and 5 Hz messages are the generated code's: checked by length

    def status_msg() -> Any:
        status.append(1)
        return codec.heartbeat_encode(0, 0, 0, 0, 0)

    enc = StateEncoder(v, BatteryModel(rho=af.air_density_kg_m3), codec, 25.0, status_msg,
                       resign=signed)
    u = np.full(af.n_actuators, 0.3)
    for k in range(25):  # GPS every 10th step, origin / status / battery at the first
        first = k == 0
        data = enc.datagram()
        want = _reference(v, ref, with_gps=k % 10 == 0, with_origin=first)
        if first:  # status and battery follow the state; skip their two frames in ref
            ref.seq = (ref.seq + 2) & 0xFF
            if signed:
                ref.signing.timestamp += 2
            assert data.startswith(want) and len(data) > len(want)
        else:
            assert data == want, k
            again = enc.again(data)
            if signed:  # signed anew: the same messages, a newer timestamp
                assert again != data and len(again) == len(data)
                ref.seq = (ref.seq + 3 if k % 10 == 0 else ref.seq + 2) & 0xFF
                ref.signing.timestamp += 3 if k % 10 == 0 else 2
            else:
                assert again == data
        v.step(u, 4)
    assert status == [1]
