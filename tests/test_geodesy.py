"""The one flat-earth projection: round trips, the textbook scale, and agreement with the HIL
codec's fused path (which keeps the same doubles inline for speed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtolftc.base.geodesy import EARTH_RADIUS_M, FlatEarth
from vtolftc.protocols.hil import HilRoundTrip, NavState, decode_hil_state, encode_hil_state


@pytest.mark.parametrize("lat0, lon0", [(0.0, 0.0), (47.397742, 8.545594), (-33.9, 151.2),
                                        (69.6, -20.0)])
def test_round_trip_and_scale(lat0, lon0):
    p = FlatEarth(lat0, lon0)
    for n, e in [(0.0, 0.0), (100.0, -50.0), (-2500.0, 3100.0)]:
        lat, lon = p.to_global(n, e)
        assert p.to_local(lat, lon) == pytest.approx((n, e), abs=1e-6)
    # one degree of latitude is R pi / 180 metres; of longitude, that times cos(lat0)
    deg = EARTH_RADIUS_M * math.pi / 180.0
    assert p.to_local(lat0 + 1.0, lon0) == pytest.approx((deg, 0.0), rel=1e-12)
    assert p.to_local(lat0, lon0 + 1.0)[1] == pytest.approx(deg * math.cos(math.radians(lat0)),
                                                            rel=1e-12)


def test_the_hil_codec_projects_as_geodesy_bit_for_bit():
    home = (47.397742, 8.545594, 488.0)
    rng = np.random.default_rng(3)
    fused = HilRoundTrip(*home)
    for _ in range(50):
        pos = rng.uniform(-2000.0, 2000.0, 3)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        nav = NavState(1000, q, rng.normal(size=3), pos, rng.normal(size=3), 12.0)
        h = encode_hil_state(nav, *home)
        lat, lon = FlatEarth(home[0], home[1]).to_global(*pos[:2].tolist())
        assert (h.lat, h.lon) == (round(lat * 1e7), round(lon * 1e7))
        back = decode_hil_state(h, *home)
        state = np.concatenate([pos, nav.vel_ned_m_s, q, nav.omega_body_rad_s])
        assert np.array_equal(fused(1000, state, 12.0).pos_ned_m, back.pos_ned_m)
