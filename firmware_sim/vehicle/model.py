"""The simulated vehicle: state, fixed-step integration, faults, sensors.

:class:`Vehicle` owns the state vector of :mod:`vtolftc.firmware_sim.vehicle.dynamics` and advances
it at 1 kHz (RK4) with the actuator commands held between calls. Simulated time is an integer
number of microseconds (``time_usec``). Faults become active at the first physics step that
starts at or after their start time, exactly, whatever the caller's batch size.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numba
import numpy as np

from vtolftc.airframe.loader import Airframe, load_airframe
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.faults import Fault, FaultError, FaultKind
from vtolftc.firmware_sim.vehicle.sensors import Home, SensorModel, SensorNoise, SensorSample
from vtolftc.rotation import dcm, quat_to_euler

_F64 = np.dtype(np.float64)


@numba.njit(cache=True)
def _all_finite(a: np.ndarray) -> bool:
    """True when every entry of the 1-D array ``a`` is finite (compiled: ~0.2 us)."""
    for i in range(a.size):  # noqa: SIM110 (a loop compiles; all(generator) does not)
        if not np.isfinite(a[i]):
            return False
    return True


@dataclass(frozen=True)
class ActiveFault:
    fault: Fault
    index: int


class Vehicle:
    """Nonlinear 6-DOF dual-system VTOL with actuator dynamics, faults and sensors.

    Commands (length ``n_actuators``, order ``airframe.actuator_names``): lift rotors and
    pushers as normalised thrust 0..1, surfaces as normalised deflection -1..1 (of
    ``surfaces.max_deflection_rad``). Values outside are clipped by the actuators.
    """

    def __init__(
        self,
        airframe: Airframe | None = None,
        *,
        state: np.ndarray | None = None,
        faults: Iterable[Fault] = (),
        wind_ned_m_s: Sequence[float] = (0.0, 0.0, 0.0),
        noise: SensorNoise | None = None,
        seed: int = 0,
        home: Home | None = None,
        dt_usec: int = 1000,
        physics: int = dyn.ALL_PHYSICS,
    ) -> None:
        self.airframe = airframe if airframe is not None else load_airframe()
        self.packed = dyn.pack(self.airframe)
        self.n_actuators = self.airframe.n_actuators
        if dt_usec <= 0:
            raise ValueError(f"dt_usec = {dt_usec}: expected a positive step in microseconds")
        self.dt_usec = int(dt_usec)
        self.physics = int(physics)
        self.time_usec = 0
        self.x = np.zeros(dyn.N_RIGID + self.n_actuators)
        if state is None:
            self.x[2] = -self.rest_height_m()
            self.x[6] = 1.0
        else:
            self.set_state(state)
        self.u = np.zeros(self.n_actuators)
        self.eff = np.ones(self.n_actuators)
        self.stuck = np.zeros(self.n_actuators, dtype=np.bool_)
        self.wind = np.array(wind_ned_m_s, dtype=float)
        if self.wind.shape != (3,) or not np.all(np.isfinite(self.wind)):
            raise ValueError(f"wind_ned_m_s = {wind_ned_m_s!r}: expected three finite numbers")
        self.fm = np.zeros(9)
        self._pending: list[ActiveFault] = []
        self.active_faults: list[ActiveFault] = []
        self.sensor_model = SensorModel(home, noise, seed, self.airframe.air_density_kg_m3)
        for f in faults:
            self.inject(f)
        self._apply_due_faults()
        self._refresh_outputs()

    # ----------------------------------------------------------------------------------------
    # State access
    # ----------------------------------------------------------------------------------------

    def rest_height_m(self) -> float:
        """Height of the CG above the ground when resting level on the landing gear (m)."""
        gear = self.airframe.landing_gear
        load = self.airframe.weight_N / len(gear.points_m)
        return float(np.max(gear.points_m[:, 2])) - load / gear.stiffness_N_m

    @property
    def state(self) -> np.ndarray:
        """A copy of the full state vector (see :mod:`vtolftc.firmware_sim.vehicle.dynamics`)."""
        return self.x.copy()

    def set_state(self, state: np.ndarray) -> None:
        s = np.asarray(state, dtype=float)
        if s.shape != self.x.shape or not np.all(np.isfinite(s)):
            raise ValueError(
                f"state of shape {s.shape}: expected {self.x.shape} finite values "
                f"(13 rigid-body states + {self.n_actuators} actuator positions)")
        self.x[:] = s
        self.x[6:10] /= np.linalg.norm(self.x[6:10])

    @property
    def position_ned_m(self) -> np.ndarray:
        return self.x[0:3].copy()

    @property
    def velocity_ned_m_s(self) -> np.ndarray:
        return self.x[3:6].copy()

    @property
    def quaternion(self) -> np.ndarray:
        return self.x[6:10].copy()

    @property
    def omega_body_rad_s(self) -> np.ndarray:
        return self.x[10:13].copy()

    @property
    def actuator_positions(self) -> np.ndarray:
        return self.x[dyn.N_RIGID:].copy()

    @property
    def euler_rad(self) -> tuple[float, float, float]:
        return quat_to_euler(self.x[6:10])

    @property
    def altitude_m(self) -> float:
        return float(-self.x[2])

    @property
    def airspeed_m_s(self) -> float:
        return float(self.fm[6])

    @property
    def force_body_N(self) -> np.ndarray:
        """Non-gravitational force on the airframe, body FRD (N)."""
        return self.fm[0:3].copy()

    @property
    def moment_body_Nm(self) -> np.ndarray:
        return self.fm[3:6].copy()

    @property
    def alpha_rad(self) -> float:
        return float(self.fm[7])

    @property
    def beta_rad(self) -> float:
        return float(self.fm[8])

    @property
    def effectiveness(self) -> np.ndarray:
        """Current effectiveness multiplier of every actuator (1 = healthy). Vehicle-side only:
        the controller must never read this (passive FTC)."""
        return self.eff.copy()

    # ----------------------------------------------------------------------------------------
    # Faults
    # ----------------------------------------------------------------------------------------

    def inject(self, fault: Fault) -> None:
        """Schedule a fault; one whose start time has passed acts from the next step."""
        if fault.actuator not in self.airframe.actuator_names:
            raise FaultError(f"unknown actuator {fault.actuator!r}; this airframe has: "
                             f"{', '.join(self.airframe.actuator_names)}")
        self._pending.append(ActiveFault(fault, self.airframe.actuator_index(fault.actuator)))
        self._pending.sort(key=lambda a: a.fault.start_usec)

    def clear_faults(self) -> None:
        """Remove every fault, active or pending (the actuators are healthy again)."""
        self._pending.clear()
        self.active_faults.clear()
        self.eff[:] = 1.0
        self.stuck[:] = False

    def _apply_due_faults(self) -> None:
        while self._pending and self._pending[0].fault.start_usec <= self.time_usec:
            a = self._pending.pop(0)
            self.active_faults.append(a)
            self.eff[a.index] *= a.fault.effectiveness
            if a.fault.kind is FaultKind.STUCK:
                self.stuck[a.index] = True

    # ----------------------------------------------------------------------------------------
    # Integration
    # ----------------------------------------------------------------------------------------

    def step(self, commands: np.ndarray | Sequence[float] | None = None, n: int = 1) -> None:
        """Hold ``commands`` (or the previous ones if None) for ``n`` physics steps."""
        if commands is not None:
            u = commands
            if type(u) is not np.ndarray or u.dtype != _F64:
                u = np.asarray(commands, dtype=float)
            if u.shape != (self.n_actuators,):
                raise ValueError(f"commands of shape {u.shape}: expected ({self.n_actuators},) "
                                 f"in the order {', '.join(self.airframe.actuator_names)}")
            if not _all_finite(u):
                raise ValueError("commands contain NaN or inf: expected finite values")
            self.u[:] = u
        remaining = int(n)
        pk = self.packed
        dt = self.dt_usec * 1e-6
        if not self._pending and remaining > 0:
            # common case: no fault due, one compiled call for the whole batch
            dyn.step_n(self.x, self.u, self.eff, self.stuck, remaining, dt, pk.P, pk.J, pk.Jinv,
                       pk.rotor_pos, pk.rotor_axis, pk.rotor_torque, pk.rotor_tmax,
                       pk.rotor_inv_v0, pk.act_tau, pk.act_rate, pk.act_min, pk.act_max,
                       pk.tab_v, pk.tab, pk.gear, self.wind, self.physics, self.fm)
            self.time_usec += remaining * self.dt_usec
            return
        while remaining > 0:
            self._apply_due_faults()
            batch = remaining
            if self._pending:
                due = self._pending[0].fault.start_usec - self.time_usec
                batch = max(1, min(batch, -(-due // self.dt_usec)))
            dyn.step_n(self.x, self.u, self.eff, self.stuck, batch, dt, pk.P, pk.J, pk.Jinv,
                       pk.rotor_pos, pk.rotor_axis, pk.rotor_torque, pk.rotor_tmax,
                       pk.rotor_inv_v0, pk.act_tau, pk.act_rate, pk.act_min, pk.act_max,
                       pk.tab_v, pk.tab, pk.gear, self.wind, self.physics, self.fm)
            self.time_usec += batch * self.dt_usec
            remaining -= batch
        self._apply_due_faults()

    def derivatives(self, state: np.ndarray | None = None,
                    commands: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(dx/dt, [F_body, M_body, Va, alpha, beta]) at a state (default: the current one)."""
        x = self.x if state is None else np.asarray(state, dtype=float)
        u = self.u if commands is None else np.asarray(commands, dtype=float)
        dx = np.empty_like(x)
        fm = np.empty(9)
        pk = self.packed
        dyn.derivatives(x, u, self.eff, self.stuck, pk.P, pk.J, pk.Jinv, pk.rotor_pos,
                        pk.rotor_axis, pk.rotor_torque, pk.rotor_tmax, pk.rotor_inv_v0,
                        pk.act_tau, pk.act_rate, pk.act_min, pk.act_max, pk.tab_v, pk.tab,
                        pk.gear, self.wind, self.physics, dx, fm)
        return dx, fm

    def _refresh_outputs(self) -> None:
        _, self.fm[:] = self.derivatives()

    # ----------------------------------------------------------------------------------------
    # Sensors
    # ----------------------------------------------------------------------------------------

    def sensors(self) -> SensorSample:
        """Sensor readings at the current time (noise per the vehicle's SensorNoise)."""
        R = dcm(self.x[6:10])
        return self.sensor_model.sample(
            self.time_usec, self.x[0:3], self.x[3:6], R, self.x[10:13],
            self.fm[0:3] / self.airframe.mass_kg, float(self.fm[6]))
