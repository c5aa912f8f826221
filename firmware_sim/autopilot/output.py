"""The autopilot's output stage: allocation of the virtual command to the actuators.

``ActiveSetAllocator`` maps ``v = [Fz, Fx, L, M, N]`` (body FRD forces [N], moments [N m])
onto all actuators at once with the nominal ``B(V)`` at the measured airspeed
(:mod:`.effectiveness`, evaluated on a 0.1 m/s airspeed grid), actuator position limits, rate
limits as per-step bounds and a warm-started active-set solve (the paper's redundancy
management). In fixed-wing after the lift rotors' ramp the ``Fz`` row is dropped and a second
allocator, with the lift rotors :data:`FW_ROTOR_RESERVE_WEIGHT` times costlier than the
surfaces in the secondary objective, keeps them as a moment reserve. Both use the nominal
``B`` (passive FTC).

It also tracks which moment axes the allocation could not achieve (the attitude
controller's anti-windup) and produces the disarmed/idle output.

Per control step (issue 24: Python calls cost as much as the arithmetic here) the shipped
``ActiveSetAllocator`` is called through ``allocate_tracked``: one compiled call, no argument
checks, no result object, that also writes the command into ``u`` and returns the
saturation tracking's mask (the same kernels, the same bits as ``allocate`` and
``_track_saturation``); any other allocator assigned to ``allocator`` goes through
``allocate``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe
from vtolftc.firmware_sim.autopilot.allocation import (
    ActiveSetAllocator,
    AllocationStatus,
    shortfall_mask,
)
from vtolftc.firmware_sim.autopilot.control_kernels import (
    W_OUT,
    W_SIZE,
    scheduled_ppid3_step_packed,
)
from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel
from vtolftc.firmware_sim.autopilot.setpoints import Setpoints

__all__ = ["ALLOCATION_WEIGHTS", "ARMED_IDLE_THROTTLE", "FW_ROTOR_RESERVE_WEIGHT", "OutputStage"]

ARMED_IDLE_THROTTLE = 0.05
#: ``AutopilotStatus.allocation_status`` text of each allocation status.
_STATUS_NAMES: dict[AllocationStatus, str] = {st: st.name.lower() for st in AllocationStatus}
#: Virtual-axis weights of the QP: [Fz (N), Fx (N), L, M, N (N m)]; moments first.
ALLOCATION_WEIGHTS = np.array([1.0, 0.5, 10.0, 10.0, 5.0])
#: Weight of the lift rotors in the fixed-wing allocator's secondary objective (surfaces and
#: pushers 1): the rotors are a reserve the QP reaches for only when the surfaces cannot
#: deliver (the primary, tracking, objective is ~1e5 times heavier per N m).
FW_ROTOR_RESERVE_WEIGHT = 30.0
#: A moment axis counts as saturated when the allocation misses its command by more than
#: ``_SAT_ATOL + _SAT_RTOL |command|`` [N m] (``shortfall_mask``'s tolerances).
_SAT_ATOL = 0.02
_SAT_RTOL = 0.02
#: ``(sat_hi, sat_lo)`` of each shortfall mask of the three moment axes (bits 0-2 short
#: upwards, 3-5 downwards): shared lists, read and never mutated.
_SAT_FLAGS = tuple(([bool(m & 1), bool(m & 2), bool(m & 4)],
                    [bool(m & 8), bool(m & 16), bool(m & 32)]) for m in range(64))


class OutputStage:
    """Allocation and actuator commands (see the module docstring).

    Parameters
    ----------
    airframe
        the airframe (actuator layout, limits, hover throttle).
    effectiveness
        the nominal effectiveness model ``B(V)``.
    setpoints
        the shared references (the virtual command ``v``).
    dt
        control period [s].

    Attributes
    ----------
    u : ndarray
        the normalised actuator commands of the last step (rotors/pushers 0..1, surfaces
        -1..1).
    status_text : str
        ``AutopilotStatus.allocation_status`` of the last step.
    saturated_steps : int
        control steps whose allocation fell short of a commanded moment (any axis).
    fz_cmd, fz_achieved : float
        body z force [N] the last allocation was asked for and achieved (nominal model;
        negative up), read by the degraded-lift monitor (:mod:`.degraded_lift`).
    """

    def __init__(self, airframe: Airframe, effectiveness: EffectivenessModel,
                 setpoints: Setpoints, dt: float) -> None:
        af = airframe
        self.effectiveness = effectiveness
        self.sp = setpoints
        self.dt = dt
        self.n_rotors = len(af.lift_rotors)
        self.i_push = [af.actuator_index(r_name) for r_name in
                       (f"pusher_{p.name}" for p in af.pushers)]
        self.n_u = af.n_actuators
        u_min = np.zeros(self.n_u)
        u_max = np.ones(self.n_u)
        n_rot_all = len(af.rotors)
        u_min[n_rot_all:] = -1.0
        rate = np.empty(self.n_u)
        for i, r in enumerate(af.rotors):
            rate[i] = r.rate_limit_per_s
        rate[n_rot_all:] = af.surfaces.rate_limit_rad_s / af.surfaces.max_deflection_rad
        self.u_min, self.u_max = u_min, u_max
        self.hover_throttle = af.weight_N / sum(r.max_thrust_N for r in af.lift_rotors)
        self.u_pref_mc = np.zeros(self.n_u)
        self.u_pref_mc[: self.n_rotors] = self.hover_throttle
        self.u_pref_fw = np.zeros(self.n_u)
        self._hi = self.u_max.copy()  # per-step upper limits handed to the allocator
        self._hi_key = (math.nan, math.nan)  # (rotor, pusher) upper limits held in _hi
        # The compiled active-set solver, warm-started from the previous command: on all QPs
        # of paper case 1 as accurate as OSQP + polish against an independent BVLS solution
        # (3.7e-5 vs 3.9e-5 in a normalised command) at a fifth of the cost (median 14 us vs
        # 64 us, benchmarks/bench_allocation.py). No wall-clock limit: a run is deterministic
        # whatever the machine's load. QPAllocator (OSQP) stays available with the same API.
        self.allocator = ActiveSetAllocator(5, u_min, u_max, w_v=ALLOCATION_WEIGHTS,
                                            u_pref=self.u_pref_mc, rate_limit=rate, dt=self.dt)
        w_fw = np.ones(self.n_u)
        w_fw[: self.n_rotors] = FW_ROTOR_RESERVE_WEIGHT
        self.allocator_fw = ActiveSetAllocator(5, u_min, u_max, w_v=ALLOCATION_WEIGHTS,
                                               w_u=w_fw, u_pref=self.u_pref_fw,
                                               rate_limit=rate, dt=self.dt)
        self.allocator_fw.stats = self.allocator.stats  # one statistics record for both
        self._fw_reserve = False  # allocator_fw active (fixed-wing after the rotor ramp)
        self._B = np.zeros((5, self.n_u))
        self._B_grid_key: int | None = None  # matrix_on_grid key of _B_grid
        self._B_grid: NDArray[np.float64] | None = None
        self._B_of: NDArray[np.float64] | None = None  # the grid B that _B (Fz row 0) is of
        self.u = np.zeros(self.n_u)
        # per moment axis: the last allocation fell short upwards / downwards (plain lists of
        # bool: read by the attitude controller's anti-windup every step)
        self.sat_hi = [False, False, False]
        self.sat_lo = [False, False, False]
        #: the same flags as one shortfall mask (bits 0-2: ``sat_hi``, 3-5: ``sat_lo``), what
        #: the attitude stage's compiled step takes
        self.sat_mask = 0
        self.saturated_steps = 0
        self.fz_cmd = 0.0
        self.fz_achieved = 0.0
        self.status_text = "idle"

    def idle(self, armed: bool) -> None:
        """Disarmed or IDLE: rotors off (idle throttle when armed), virtual command 0,
        allocators reset at that command."""
        u = self.u
        u[:] = 0.0
        if armed:
            u[: self.n_rotors] = ARMED_IDLE_THROTTLE
        self.sp.v[:] = 0.0
        self.status_text = "idle"
        self.allocator.reset(u)
        self._fw_reserve = False

    def clear_saturation(self) -> None:
        """Forget which axes the last allocation fell short on (loops reset)."""
        self.sat_hi = [False, False, False]
        self.sat_lo = [False, False, False]
        self.sat_mask = 0

    def allocate(self, V: float, tau: NDArray[np.float64] | None, reserve: bool,
                 rotor_hi: float, pusher_hi: float, u_pref: NDArray[np.float64],
                 ppid: tuple[Any, ...] | None = None) -> NDArray[np.float64]:
        """Allocate the virtual command (``setpoints.v[0:2]`` forces [N], ``tau`` torques
        [N m]) to the actuators at airspeed ``V`` [m/s]; returns a copy of the commands.

        With ``ppid`` (``AttitudeStage.kernel_step_args``'s answer; ``tau`` then unused) the
        torques are that compiled P-PID step's, run first: in the allocation's compiled
        call (``allocate_tracked(..., ppid=...)``), or on its own before a replaced
        allocator."""
        # B(V) on a 0.1 m/s airspeed grid: the allocator rebuilds its Hessian only when B changes
        # (every ~12 steps in the transition instead of every step); the dynamic pressure
        # differs from the exact one by < 1 % above 10 m/s, far below the faults' 20-50 %.
        k_grid = round(V / 0.1) if V > 0.0 else 0  # matrix_on_grid's key (V is finite here)
        if k_grid != self._B_grid_key:
            self._B_grid = self.effectiveness.matrix_on_grid(V, 0.1)
            self._B_grid_key = k_grid
        B = self._B_grid
        if reserve:  # no z force command: the lift rotors' row is zeroed
            if B is not self._B_of:  # the grid's B is cached and read-only: copy on change
                np.copyto(self._B, B)
                self._B[0, :] = 0.0
                self._B_of = B
            B = self._B
        u = self.u
        v = self.sp.v
        hi = self._hi
        if rotor_hi != self._hi_key[0] or pusher_hi != self._hi_key[1]:  # rarely changes
            hi[: self.n_rotors] = rotor_hi
            for i in self.i_push:
                hi[i] = pusher_hi
            self._hi_key = (rotor_hi, pusher_hi)
        if reserve != self._fw_reserve:  # hand over, warm-started at the current command
            (self.allocator_fw if reserve else self.allocator).reset(u)
            self._fw_reserve = reserve
        alloc = self.allocator_fw if reserve else self.allocator
        if type(alloc) is ActiveSetAllocator and "allocate" not in alloc.__dict__ \
                and (ppid is not None or type(tau) is np.ndarray):
            # v[2:] = tau, allocate(v, B, u_max=hi, u_pref=u_pref) and _track_saturation(v,
            # B u) in one compiled call, the command written into u (the arrays here are the
            # kernel's types by construction); bit for bit the same
            if ppid is None:
                status, mask, self.fz_achieved = alloc.allocate_tracked(
                    v, B, hi, u_pref, u, 2, _SAT_ATOL, _SAT_RTOL, v_tail=tau)
            else:  # the P-PID step and the allocation in one compiled call
                status, mask, self.fz_achieved = alloc.allocate_tracked(
                    v, B, hi, u_pref, u, 2, _SAT_ATOL, _SAT_RTOL, ppid=ppid)
            self.fz_cmd = v.item(0)
            self.sat_hi, self.sat_lo = _SAT_FLAGS[mask]
            self.sat_mask = mask
            if mask:
                self.saturated_steps += 1
        else:  # an allocator (or its allocate) replaced by a benchmark or a test
            if ppid is not None:  # the attitude stage's step, on its own
                scheduled_ppid3_step_packed(*ppid)
                tau = ppid[5][W_OUT:W_SIZE]
            v[2:] = tau
            res = alloc.allocate(v, B, u_max=hi, u_pref=u_pref)
            status = res.status
            self._track_saturation(v, res.v_achieved)
            u[:] = res.u
        self.status_text = _STATUS_NAMES[status]
        return u.copy()

    def _track_saturation(self, v: NDArray[np.float64], achieved: NDArray[np.float64]) -> None:
        """Which moment axes the allocation could not achieve, and in which direction."""
        mask = shortfall_mask(v, achieved, 2, _SAT_ATOL, _SAT_RTOL)
        self.fz_cmd = v.item(0)
        self.fz_achieved = achieved.item(0)
        self.sat_hi, self.sat_lo = _SAT_FLAGS[mask]
        self.sat_mask = mask
        if mask:
            self.saturated_steps += 1
