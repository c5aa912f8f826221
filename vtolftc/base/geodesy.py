"""The flat-earth projection between local NED positions and geodetic coordinates, in one place.

Every part of the project that turns a position north/east of home into latitude/longitude or
back (the HIL codec, the simulated GPS, the navigator, the ULog writer, mission runners and the
dashboard) uses this projection, so that they agree to the last bit: a sphere of radius
:data:`EARTH_RADIUS_M` (WGS-84's equatorial radius), the east scale taken at home's latitude.
Good to centimetres within a few kilometres of home, which is the vehicle's range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["EARTH_RADIUS_M", "FlatEarth"]

#: Radius of the projection's sphere [m] (WGS-84 semi-major axis).
EARTH_RADIUS_M = 6_378_137.0


@dataclass(frozen=True)
class FlatEarth:
    """Projection about a home point.

    Parameters
    ----------
    lat0_deg, lon0_deg : float
        Home latitude and longitude [deg].

    Examples
    --------
    >>> p = FlatEarth(47.0, 8.0)
    >>> lat, lon = p.to_global(100.0, -50.0)
    >>> [round(v, 9) for v in p.to_local(lat, lon)]
    [100.0, -50.0]
    """

    lat0_deg: float
    lon0_deg: float
    #: cos(home latitude), computed once (the same double every caller used to compute inline)
    cos_lat0: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "cos_lat0", math.cos(math.radians(self.lat0_deg)))

    def to_global(self, north_m: float, east_m: float) -> tuple[float, float]:
        """(lat, lon) [deg] of the point ``north_m``, ``east_m`` [m] from home."""
        return (self.lat0_deg + math.degrees(north_m / EARTH_RADIUS_M),
                self.lon0_deg + math.degrees(east_m / (EARTH_RADIUS_M * self.cos_lat0)))

    def to_local(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        """(north, east) [m] from home of the point at ``lat_deg``, ``lon_deg`` [deg]."""
        return (math.radians(lat_deg - self.lat0_deg) * EARTH_RADIUS_M,
                math.radians(lon_deg - self.lon0_deg) * EARTH_RADIUS_M * self.cos_lat0)
