"""Sensor models of the simulated vehicle: IMU, magnetometer, barometer, airspeed, GPS.

Outputs are in the units of MAVLink's HIL_SENSOR / HIL_GPS so they can be sent as they are:
specific force in m/s^2 (body FRD), angular rate in rad/s (body FRD), magnetic field in gauss
(body FRD), absolute and differential pressure in hPa, GPS in degrees, metres and m/s (NED).
Noise is optional and seeded: the same seed gives the same readings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vtolftc.base.geodesy import FlatEarth

SEA_LEVEL_PRESSURE_HPA = 1013.25
SEA_LEVEL_TEMPERATURE_C = 15.0


@dataclass(frozen=True)
class Home:
    """Geodetic origin of the local NED frame (default: Politecnico di Milano, Bovisa)."""

    lat_deg: float = 45.5027
    lon_deg: float = 9.1566
    alt_m: float = 122.0
    # Earth field in NED (gauss) near the home location.
    mag_ned_gauss: tuple[float, float, float] = (0.222, 0.0085, 0.418)


@dataclass(frozen=True)
class SensorNoise:
    """One-sigma white noise of each sensor (zero everywhere: exact readings)."""

    accel_m_s2: float = 0.0
    gyro_rad_s: float = 0.0
    mag_gauss: float = 0.0
    baro_hpa: float = 0.0
    diff_pressure_hpa: float = 0.0
    gps_pos_m: float = 0.0
    gps_vel_m_s: float = 0.0

    @classmethod
    def typical(cls) -> SensorNoise:
        """Levels of a small autopilot's MEMS IMU, baro and u-blox GPS."""
        return cls(accel_m_s2=0.05, gyro_rad_s=0.004, mag_gauss=0.003, baro_hpa=0.012,
                   diff_pressure_hpa=0.005, gps_pos_m=0.3, gps_vel_m_s=0.05)


@dataclass(frozen=True)
class SensorSample:
    """One set of readings at ``time_usec`` (simulated microseconds)."""

    time_usec: int
    accel_m_s2: np.ndarray      # specific force, body FRD
    gyro_rad_s: np.ndarray      # body FRD
    mag_gauss: np.ndarray       # body FRD
    abs_pressure_hpa: float
    diff_pressure_hpa: float
    pressure_alt_m: float
    temperature_c: float
    airspeed_m_s: float         # indicated (from differential pressure, sea-level density)
    gps_lat_deg: float
    gps_lon_deg: float
    gps_alt_m: float
    gps_vel_ned_m_s: np.ndarray


def pressure_at_altitude_hpa(alt_m: float) -> float:
    """ISA troposphere static pressure at geometric altitude ``alt_m`` above sea level."""
    return SEA_LEVEL_PRESSURE_HPA * (1.0 - 2.25577e-5 * alt_m) ** 5.25588


def altitude_from_pressure_m(p_hpa: float) -> float:
    """Inverse of :func:`pressure_at_altitude_hpa`."""
    return (1.0 - (p_hpa / SEA_LEVEL_PRESSURE_HPA) ** (1.0 / 5.25588)) / 2.25577e-5


class SensorModel:
    """Turns the true state into sensor readings, with optional seeded noise."""

    def __init__(self, home: Home | None = None, noise: SensorNoise | None = None,
                 seed: int = 0, air_density_kg_m3: float = 1.225) -> None:
        self.home = home or Home()
        self.noise = noise or SensorNoise()
        self.rng = np.random.default_rng(seed)
        self.rho = air_density_kg_m3
        self._mag_ned = np.array(self.home.mag_ned_gauss)
        self._proj: FlatEarth | None = None

    def _n(self, sigma: float, size: int | None = None) -> np.ndarray | float:
        """Noise of one-sigma ``sigma`` (``size`` draws, or a scalar); for ``sigma == 0`` the
        scalar 0.0 (added to an array it gives the bits an array of zeros gives, -0.0 + 0.0
        included, without making one: the noise-free SITL vehicle draws nothing)."""
        if sigma == 0.0:
            return 0.0
        return self.rng.normal(0.0, sigma, size)

    def _projection(self) -> FlatEarth:
        """The flat-earth projection about :attr:`home` (made again if home changed)."""
        h = self.home
        proj = self._proj
        if proj is None or proj.lat0_deg != h.lat_deg or proj.lon0_deg != h.lon_deg:
            proj = self._proj = FlatEarth(h.lat_deg, h.lon_deg)
        return proj

    def sample(self, time_usec: int, pos_ned: np.ndarray, vel_ned: np.ndarray,
               R_body_to_ned: np.ndarray, omega_body: np.ndarray,
               specific_force_body: np.ndarray, airspeed_m_s: float) -> SensorSample:
        """One sensor sample of the true state (noise from the model's seeded generator).

        Parameters
        ----------
        time_usec : int
            Simulated time [us].
        pos_ned, vel_ned : ndarray, shape (3,)
            Position about home [m] and ground velocity [m/s], NED.
        R_body_to_ned : ndarray, shape (3, 3)
            Attitude as a rotation matrix body FRD -> NED.
        omega_body : ndarray, shape (3,)
            Body rates p, q, r [rad/s], FRD.
        specific_force_body : ndarray, shape (3,)
            Specific force the accelerometer measures [m/s^2], FRD.
        airspeed_m_s : float
            True airspeed [m/s].

        Returns
        -------
        SensorSample
            What HIL_SENSOR and HIL_GPS carry, in SI units.
        """
        n = self.noise
        alt = self.home.alt_m - float(pos_ned[2])
        p_abs = pressure_at_altitude_hpa(alt) + float(self._n(n.baro_hpa))
        q_dyn_hpa = 0.5 * self.rho * airspeed_m_s**2 / 100.0 + float(self._n(n.diff_pressure_hpa))
        ias = math.sqrt(max(0.0, 2.0 * q_dyn_hpa * 100.0 / 1.225))
        pn = float(pos_ned[0]) + float(self._n(n.gps_pos_m))
        pe = float(pos_ned[1]) + float(self._n(n.gps_pos_m))
        pd = float(pos_ned[2]) + float(self._n(n.gps_pos_m))
        lat, lon = self._projection().to_global(pn, pe)
        return SensorSample(
            time_usec=int(time_usec),
            accel_m_s2=np.asarray(specific_force_body, dtype=float) + self._n(n.accel_m_s2, 3),
            gyro_rad_s=np.asarray(omega_body, dtype=float) + self._n(n.gyro_rad_s, 3),
            mag_gauss=R_body_to_ned.T @ self._mag_ned + self._n(n.mag_gauss, 3),
            abs_pressure_hpa=p_abs,
            diff_pressure_hpa=q_dyn_hpa,
            pressure_alt_m=altitude_from_pressure_m(p_abs),
            temperature_c=SEA_LEVEL_TEMPERATURE_C - 0.0065 * alt,
            airspeed_m_s=ias,
            gps_lat_deg=lat,
            gps_lon_deg=lon,
            gps_alt_m=self.home.alt_m - pd,
            gps_vel_ned_m_s=np.asarray(vel_ned, dtype=float) + self._n(n.gps_vel_m_s, 3),
        )


@dataclass(frozen=True)
class StateNoise:
    """One-sigma white errors of the state estimate the vehicle reports (HIL_STATE_QUATERNION).

    The in-process runner and the HIL link hand the autopilot the vehicle's state as an
    estimator would: with this noise, the reported attitude is the truth rotated by a small
    random rotation (``attitude_rad`` per body axis), rates, NED position and velocity and
    airspeed get additive errors. Levels of :meth:`typical` are those of a small autopilot's
    EKF output (not of the raw sensors, which it filters).
    """

    attitude_rad: float = 0.0
    rate_rad_s: float = 0.0
    position_m: float = 0.0
    velocity_m_s: float = 0.0
    airspeed_m_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("attitude_rad", "rate_rad_s", "position_m", "velocity_m_s",
                     "airspeed_m_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0.0):
                raise ValueError(f"StateNoise.{name} = {v!r}: expected a sigma >= 0")

    @classmethod
    def typical(cls) -> StateNoise:
        """0.2 deg attitude, 0.004 rad/s rates (the gyro), 0.1 m, 0.05 m/s, 0.3 m/s airspeed."""
        return cls(attitude_rad=math.radians(0.2), rate_rad_s=0.004, position_m=0.1,
                   velocity_m_s=0.05, airspeed_m_s=0.3)


class StateEstimateNoise:
    """Seeded generator of noisy state estimates (see :class:`StateNoise`)."""

    def __init__(self, noise: StateNoise, seed: int = 0) -> None:
        self.noise = noise
        self.rng = np.random.default_rng(seed)

    def apply(self, x: np.ndarray, airspeed_m_s: float) -> tuple[np.ndarray, float]:
        """A noisy copy of the rigid-body part of ``x`` (13,) and of the airspeed [m/s].

        Draws 13 normal numbers per call, always in the same order (position, velocity,
        attitude, rates, airspeed), so the sequence depends only on the seed and the number
        of calls.
        """
        n = self.noise
        z = self.rng.standard_normal(13)
        out = np.array(x[:13], dtype=float)
        out[0:3] += n.position_m * z[0:3]
        out[3:6] += n.velocity_m_s * z[3:6]
        # small body-axis rotation: q_est = q (x) [1, dtheta / 2], renormalised
        d = 0.5 * n.attitude_rad * z[6:9]
        w, a, b, c = out[6:10]
        q = np.array([w - a * d[0] - b * d[1] - c * d[2],
                      a + w * d[0] + b * d[2] - c * d[1],
                      b + w * d[1] + c * d[0] - a * d[2],
                      c + w * d[2] + a * d[1] - b * d[0]])
        out[6:10] = q / np.linalg.norm(q)
        out[10:13] += n.rate_rad_s * z[9:12]
        return out, max(0.0, float(airspeed_m_s) + n.airspeed_m_s * float(z[12]))
