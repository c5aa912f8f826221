"""The simulated vehicle: state, fixed-step integration, faults, sensors.

:class:`Vehicle` owns the state vector of :mod:`vtolftc.firmware_sim.vehicle.dynamics` and advances
it at 1 kHz (RK4) with the actuator commands held between calls. Simulated time is an integer
number of microseconds (``time_usec``). Faults become active at the first physics step that
starts at or after their start time, exactly, whatever the caller's batch size.

The physical vehicle may differ from the airframe file (``perturbation``: mass, inertia, CG
offset), fly in a :class:`~vtolftc.firmware_sim.vehicle.wind.WindField` (steady wind and
gusts, evaluated at every physics step) and report a noisy state estimate
(``state_noise``). None of this reaches the autopilot except through the state it is sent:
it keeps flying on the nominal airframe (passive FTC).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numba
import numpy as np

from vtolftc.airframe.loader import Airframe, load_airframe
from vtolftc.base.nrt import borrowed
from vtolftc.base.rotation import dcm, quat_to_euler
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.faults import Fault, FaultError, FaultKind
from vtolftc.firmware_sim.vehicle.sensors import (
    Home,
    SensorModel,
    SensorNoise,
    SensorSample,
    StateEstimateNoise,
    StateNoise,
)
from vtolftc.firmware_sim.vehicle.wind import WindField
from vtolftc.protocols.hil import wire_commands, wire_round

_F64 = np.dtype(np.float64)


@numba.njit(cache=True)
def _take_commands(src: np.ndarray, dst: np.ndarray) -> bool:
    """Copy the 1-D array ``src`` into ``dst`` when every entry is finite and return True;
    else leave ``dst`` as it is and return False (compiled: one call per control step)."""
    for i in range(src.size):
        if not np.isfinite(src[i]):
            return False
    for i in range(src.size):
        dst[i] = src[i]
    return True


@numba.njit(cache=True)
def _take_and_step(src, x, u, eff, stuck, n, dt, buf, layout, wind, flags, fm,
                   memo):  # pragma: no cover - compiled
    """``_take_commands(src, u)`` then, when it took them, ``dynamics.step_n_flat_memo(x, u,
    eff, stuck, n, dt, buf, layout, wind, flags, fm, memo)``, in one compiled call (one
    dispatch and one unboxing of the arrays fewer per control step; the same kernels, the
    same bits). Returns False, nothing changed, when ``src`` has a non-finite entry."""
    if not _take_commands(src, u):
        return False
    dyn.step_n_flat_memo(x, u, eff, stuck, n, dt, buf, layout, wind, flags, fm, memo)
    return True


@numba.njit(cache=True)
def take_and_step_packed(src, ws, stuck, n, dt, buf, layout, flags,
                          wire):  # pragma: no cover - compiled
    """:func:`_take_and_step` on the vehicle's own float arrays packed into one workspace
    ``ws`` (``Vehicle._pack``: ``x``, ``u``, ``eff``, ``wind``, ``fm``, then ``memo``; ``x``
    has ``N_RIGID + n`` entries for the ``n = src.size`` actuators): 5 array arguments
    instead of 10 (each costs its own type check and unboxing, ~0.15-0.2 us a call). With
    ``wire`` the commands are first rounded as the HIL link carries them
    (:func:`~vtolftc.protocols.hil.wire_round`, then checked). The same kernels on the same
    numbers: the same bits."""
    if wire:
        src = wire_round(src)
    # views without reference counting for the callees (base.nrt: the caller holds them)
    ws = borrowed(ws)
    stuck = borrowed(stuck)
    buf = borrowed(buf)
    layout = borrowed(layout)
    x, u, eff, wind, fm, memo = packed_views(ws, src.size)
    return _take_and_step(src, x, u, eff, stuck, n, dt, buf, layout, wind, flags, fm, memo)


@numba.njit(cache=True)
def packed_views(ws, na):  # pragma: no cover - compiled
    """The views ``x``, ``u``, ``eff``, ``wind``, ``fm``, ``memo`` of the workspace ``ws``
    (``Vehicle._WS_PARTS``' layout for ``na`` actuators: ``x`` has ``N_RIGID + na`` entries,
    ``wind`` 3, ``fm`` 9)."""
    ie = dyn.N_RIGID + 2 * na  # eff
    iw = ie + na  # wind
    return (ws[0:ie - na], ws[ie - na:ie], ws[ie:iw], ws[iw:iw + 3], ws[iw + 3:iw + 12],
            ws[iw + 12:])


@dataclass(frozen=True)
class Perturbation:
    """The physical vehicle off the airframe file: ``mass_scale`` x mass, ``inertia_scale`` x
    the principal inertias (per body axis), CG moved by ``cg_offset_m`` (body FRD, m); see
    :func:`vtolftc.firmware_sim.vehicle.dynamics.perturb`."""

    mass_scale: float = 1.0
    inertia_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    cg_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def is_identity(self) -> bool:
        """True when nothing is changed (scales 1, CG offset 0): the airframe file as it is."""
        return (self.mass_scale == 1.0 and tuple(self.inertia_scale) == (1.0, 1.0, 1.0)
                and tuple(self.cg_offset_m) == (0.0, 0.0, 0.0))


@dataclass(frozen=True)
class ActiveFault:
    """A fault waiting for (or in) effect; ``index``: its place in the actuator vector."""
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
        perturbation: Perturbation | None = None,
        wind: WindField | None = None,
        state_noise: StateNoise | None = None,
    ) -> None:
        self.airframe = airframe if airframe is not None else load_airframe()
        self.packed = dyn.pack(self.airframe)
        self.perturbation = perturbation
        if perturbation is not None and not perturbation.is_identity:
            self.packed = dyn.perturb(self.packed, perturbation.mass_scale,
                                      tuple(perturbation.inertia_scale),
                                      tuple(perturbation.cg_offset_m))
        self.mass_kg = float(self.packed.P[dyn.P_MASS])
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
        # a wind field replaces the constant wind; gusts make it time-varying
        self.wind_field = wind
        self._gusty = wind is not None and bool(wind.gusts)
        if wind is not None:
            wind.at(0.0, self.wind)
        self.state_noise = state_noise
        self._estimate_noise = (StateEstimateNoise(state_noise, seed)
                                if state_noise is not None else None)
        self.fm = np.zeros(9)
        self._packed_args: tuple = (None,)  # (packed, flatten_packed(packed)...)
        # the last control step's final derivative evaluation, for the next one's first
        # stage (dynamics.step_n_memo; memo[0] = 0: none): cleared when the airframe changes
        self._memo = np.zeros(dyn.memo_size(self.x.size, self.n_actuators))
        self._vws = np.empty(0)
        self._pack()
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
        load = self.mass_kg * self.airframe.gravity_m_s2 / len(gear.points_m)
        return float(np.max(self.packed.gear[:, 2])) - load / gear.stiffness_N_m

    @property
    def state(self) -> np.ndarray:
        """A copy of the full state vector (see :mod:`vtolftc.firmware_sim.vehicle.dynamics`)."""
        return self.x.copy()

    _WS_PARTS = ("x", "u", "eff", "wind", "fm", "_memo")
    """The float arrays that are views of ``_vws``, in :func:`take_and_step_packed`'s
    order."""

    def _pack(self) -> None:
        """Move ``_WS_PARTS`` (same values) into one float64 workspace ``_vws``, each
        attribute becoming a view of its part (the control step's kernel takes the one
        array)."""
        if self.wind.shape != (3,) or self.fm.shape != (9,):  # the layout the kernel assumes
            raise AssertionError("wind or fm of unexpected size")
        self._vws = np.concatenate([getattr(self, name) for name in self._WS_PARTS])
        self._link_views()

    def _link_views(self) -> None:
        """Make the ``_WS_PARTS`` attributes views of ``_vws`` again."""
        o = 0
        for name in self._WS_PARTS:
            k = getattr(self, name).size
            setattr(self, name, self._vws[o:o + k])
            o += k

    def __setstate__(self, state: dict[str, object]) -> None:
        """A copied or unpickled vehicle (numpy copies every array on its own) links its
        state arrays to its own workspace again."""
        self.__dict__.update(state)
        self._link_views()

    def set_state(self, state: np.ndarray) -> None:
        """Overwrite the full state (13 rigid-body states, then the actuator positions).

        The quaternion part is renormalised.

        Parameters
        ----------
        state : numpy.ndarray
            ``[p_ned (m), v_ned (m/s), q (w, x, y, z), omega_frd (rad/s), actuators]``.

        Raises
        ------
        ValueError
            wrong shape or a non-finite entry.
        """
        s = np.asarray(state, dtype=float)
        if s.shape != self.x.shape or not np.all(np.isfinite(s)):
            raise ValueError(
                f"state of shape {s.shape}: expected {self.x.shape} finite values "
                f"(13 rigid-body states + {self.n_actuators} actuator positions)")
        self.x[:] = s
        self.x[6:10] /= np.linalg.norm(self.x[6:10])

    @property
    def position_ned_m(self) -> np.ndarray:
        """Position in the NED world frame (m), a copy."""
        return self.x[0:3].copy()

    @property
    def velocity_ned_m_s(self) -> np.ndarray:
        """Velocity in the NED world frame (m/s), a copy."""
        return self.x[3:6].copy()

    @property
    def quaternion(self) -> np.ndarray:
        """Attitude quaternion (w, x, y, z), body FRD to NED world, a copy."""
        return self.x[6:10].copy()

    @property
    def omega_body_rad_s(self) -> np.ndarray:
        """Angular rate in the body FRD frame (rad/s), a copy."""
        return self.x[10:13].copy()

    @property
    def actuator_positions(self) -> np.ndarray:
        """Actuator states after their dynamics (motor commands and servo angles), a copy."""
        return self.x[dyn.N_RIGID:].copy()

    @property
    def euler_rad(self) -> tuple[float, float, float]:
        """ZYX Euler angles (roll, pitch, yaw) in rad, of the current attitude."""
        return quat_to_euler(self.x[6:10])

    @property
    def altitude_m(self) -> float:
        """Height above the NED origin, ``-p_down`` (m)."""
        return float(-self.x[2])

    @property
    def airspeed_m_s(self) -> float:
        """True airspeed of the last force evaluation (m/s)."""
        return float(self.fm[6])

    @property
    def force_body_N(self) -> np.ndarray:
        """Non-gravitational force on the airframe, body FRD (N)."""
        return self.fm[0:3].copy()

    @property
    def moment_body_Nm(self) -> np.ndarray:
        """Moment about the CG of the last force evaluation, body FRD (N m)."""
        return self.fm[3:6].copy()

    @property
    def alpha_rad(self) -> float:
        """Angle of attack of the last force evaluation (rad)."""
        return float(self.fm[7])

    @property
    def beta_rad(self) -> float:
        """Sideslip angle of the last force evaluation (rad)."""
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

    def step(self, commands: np.ndarray | Sequence[float] | None = None, n: int = 1, *,
             wire: bool = False) -> None:
        """Hold ``commands`` (or the previous ones if None) for ``n`` physics steps; with
        ``wire`` the commands as HIL_ACTUATOR_CONTROLS carries them
        (:func:`~vtolftc.protocols.hil.wire_commands` of them, float32)."""
        args = self.control_step_args(commands) if n > 0 else None
        if args is not None:
            # the common case of a control step: the commands taken and the whole batch
            # flown in one compiled call (the branches below, the same kernels)
            if not take_and_step_packed(commands, args[0], args[1], int(n), args[2],
                                         args[3], args[4], args[5], wire):
                raise ValueError("commands contain NaN or inf: expected finite values")
            self.time_usec += int(n) * self.dt_usec
            return
        if wire and commands is not None:
            commands = wire_commands(commands)
        if commands is not None:
            u = commands
            if type(u) is not np.ndarray or u.dtype != _F64:
                u = np.asarray(commands, dtype=float)
            if u.shape != (self.n_actuators,):
                raise ValueError(f"commands of shape {u.shape}: expected ({self.n_actuators},) "
                                 f"in the order {', '.join(self.airframe.actuator_names)}")
            if not _take_commands(u, self.u):
                raise ValueError("commands contain NaN or inf: expected finite values")
        remaining = int(n)
        pk = self.packed
        dt = self.dt_usec * 1e-6
        # the packed airframe's 15 arrays flattened into one buffer once per ``packed`` object
        pa = self._packed_args
        if pa[0] is not pk:
            pa = self._packed_args = (pk, *dyn.flatten_packed(pk))
            self._memo[0] = 0.0  # another airframe: the memo's derivative is not its own
        buf, lay = pa[1], pa[2]
        if self._gusty:
            self._step_gusty(remaining, dt, buf, lay)
            return
        if not self._pending and remaining > 0:
            # common case: no fault due, one compiled call for the whole batch
            dyn.step_n_flat(self.x, self.u, self.eff, self.stuck, remaining, dt, buf, lay,
                            self.wind, self.physics, self.fm)
            self.time_usec += remaining * self.dt_usec
            return
        while remaining > 0:
            self._apply_due_faults()
            batch = remaining
            if self._pending:
                due = self._pending[0].fault.start_usec - self.time_usec
                batch = max(1, min(batch, -(-due // self.dt_usec)))
            dyn.step_n_flat(self.x, self.u, self.eff, self.stuck, batch, dt, buf, lay,
                            self.wind, self.physics, self.fm)
            self.time_usec += batch * self.dt_usec
            remaining -= batch
        self._apply_due_faults()

    def control_step_args(self, commands: object) -> tuple | None:
        """The arguments after ``src`` and ``n`` of :func:`take_and_step_packed` with which
        :meth:`step` flies ``commands`` in one compiled call: ``(ws, stuck, dt [s], buf,
        layout, flags)``; None when it cannot (commands not float64 of the vehicle's shape,
        gusts, a fault pending, the airframe's flattened arrays not current). For a caller
        that fuses that kernel into its own compiled call (the in-process runner): after such
        a call that returned True, it advances ``time_usec`` by ``n * dt_usec`` as
        :meth:`step` does."""
        pa = self._packed_args
        if (type(commands) is np.ndarray and commands.dtype is _F64
                and commands.shape == self.u.shape and not self._gusty and not self._pending
                and pa[0] is self.packed):
            return self._vws, self.stuck, self.dt_usec * 1e-6, pa[1], pa[2], self.physics
        return None

    def _step_gusty(self, n: int, dt: float, buf: np.ndarray, lay: np.ndarray) -> None:
        """``n`` physics steps one at a time, the wind field evaluated at the start of each
        (``buf``, ``lay``: the airframe as ``dynamics.flatten_packed``)."""
        wf = self.wind_field
        assert wf is not None
        for _ in range(n):
            self._apply_due_faults()
            wf.at(self.time_usec * 1e-6, self.wind)
            dyn.step_n_flat(self.x, self.u, self.eff, self.stuck, 1, dt, buf, lay, self.wind,
                            self.physics, self.fm)
            self.time_usec += self.dt_usec
        self._apply_due_faults()
        wf.at(self.time_usec * 1e-6, self.wind)

    def estimated_state(self) -> tuple[np.ndarray, float]:
        """The state as reported to the autopilot: (rigid-body state (13,) or the full state,
        airspeed m/s). Without ``state_noise`` this is the truth itself (``self.x``, no copy);
        with it, a noisy copy (see :class:`~vtolftc.firmware_sim.vehicle.sensors.StateNoise`)
        drawn from the vehicle's seeded generator."""
        if self._estimate_noise is None:
            return self.x, float(self.fm[6])
        return self._estimate_noise.apply(self.x, float(self.fm[6]))

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
            self.fm[0:3] / self.mass_kg, float(self.fm[6]))
