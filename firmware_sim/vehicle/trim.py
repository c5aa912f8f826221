"""Trim of the nonlinear vehicle: hover, and straight level flight at a given airspeed.

Every trim is solved on the nonlinear equations of motion themselves (the compiled
:func:`vtolftc.firmware_sim.vehicle.dynamics.derivatives`), so a trimmed state stays still when
simulated. Two level-flight variants:

- ``wing``: the wing carries the weight; unknowns pitch, elevator, pusher thrust; the lift
  rotors are stopped. Exists only above the stall speed.
- ``rotor-assisted``: pitch is fixed (default 0, as during a transition); the lift rotors carry
  what the wing does not, spread in the hover-trim proportions (no net moment); unknowns rotor
  collective, elevator, pusher thrust.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from vtolftc.airframe.loader import Airframe, load_airframe
from vtolftc.base.rotation import euler_to_quat
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.model import Vehicle


class TrimError(RuntimeError):
    """No trim exists (or none was found) at the requested condition."""


@dataclass(frozen=True)
class TrimPoint:
    """A trimmed flight condition. Angles in rad, actuator values normalised as commands."""

    mode: str                      # "hover", "wing" or "rotor-assisted"
    airspeed_m_s: float
    altitude_m: float
    state: np.ndarray              # full state vector, actuator positions == commands
    commands: np.ndarray           # (n_actuators,)
    pitch_rad: float
    alpha_rad: float
    elevator_rad: float
    pusher_thrust_fraction: float  # each pusher, of its max thrust
    lift_rotor_fractions: np.ndarray  # (n_lift,) of max thrust
    lift_coefficient: float
    residual: float                # max |acceleration| left (m/s^2 or rad/s^2)
    rotor_lift_share: float = 0.0  # fraction of the weight carried by the lift rotors


def _base_state(af: Airframe, altitude_m: float, airspeed_m_s: float, pitch: float) -> np.ndarray:
    x = np.zeros(dyn.N_RIGID + af.n_actuators)
    x[2] = -altitude_m
    x[3] = airspeed_m_s
    x[6:10] = euler_to_quat(0.0, pitch, 0.0)
    return x


def _accel(v: Vehicle, x: np.ndarray) -> np.ndarray:
    """Translational (NED) and rotational accelerations at a state whose actuators = commands."""
    dx, _ = v.derivatives(x, x[dyn.N_RIGID:])
    return np.concatenate([dx[3:6], dx[10:13]])


def trim_hover(airframe: Airframe | None = None, altitude_m: float = 30.0) -> TrimPoint:
    """Hover at rest, level, heading north: lift-rotor thrusts that cancel weight and moments.

    The eight thrusts are underdetermined by four equations (vertical force, three moments):
    the minimum-norm deviation from an equal split is taken, solved by Newton iterations on
    the nonlinear model.
    """
    af = airframe if airframe is not None else load_airframe()
    v = Vehicle(af)
    n_lift = len(af.lift_rotors)
    x = _base_state(af, altitude_m, 0.0, 0.0)
    share = af.weight_N / sum(r.max_thrust_N for r in af.lift_rotors)
    x[dyn.N_RIGID:dyn.N_RIGID + n_lift] = share
    idx = slice(dyn.N_RIGID, dyn.N_RIGID + n_lift)
    rows = [2, 3, 4, 5]  # NED z acceleration, p', q', r'
    for _ in range(20):
        r = _accel(v, x)[rows]
        if np.max(np.abs(r)) < 1e-12:
            break
        Jm = np.empty((4, n_lift))
        h = 1e-6
        for j in range(n_lift):
            xp = x.copy()
            xp[dyn.N_RIGID + j] += h
            Jm[:, j] = (_accel(v, xp)[rows] - r) / h
        x[idx] -= np.linalg.pinv(Jm) @ r
    acc = _accel(v, x)
    fr = x[idx].copy()
    if np.any(fr < 0) or np.any(fr > 1):
        raise TrimError(f"hover needs lift-rotor thrusts {np.round(fr, 3)} outside 0..1")
    return TrimPoint("hover", 0.0, altitude_m, x.copy(), x[dyn.N_RIGID:].copy(), 0.0, 0.0, 0.0,
                     0.0, fr, 0.0, float(np.max(np.abs(acc))), rotor_lift_share=1.0)


def trim_level_flight(
    airframe: Airframe | None = None,
    airspeed_m_s: float = 18.0,
    altitude_m: float = 30.0,
    pitch_rad: float | None = None,
) -> TrimPoint:
    """Straight level flight at ``airspeed_m_s`` (no wind, heading north).

    ``pitch_rad=None``: wing-borne trim (lift rotors stopped). A number: rotor-assisted trim
    at that pitch. Raises :class:`TrimError` when no trim exists within the actuator limits
    or below the stall.
    """
    af = airframe if airframe is not None else load_airframe()
    if not (math.isfinite(airspeed_m_s) and airspeed_m_s > 0):
        raise ValueError(f"airspeed_m_s = {airspeed_m_s!r}: expected a positive speed (m/s)")
    v = Vehicle(af)
    n_lift = len(af.lift_rotors)
    n_rot = len(af.rotors)
    i_elev = af.actuator_index("elevator")
    hover = trim_hover(af, altitude_m)
    dist = hover.lift_rotor_fractions / np.mean(hover.lift_rotor_fractions)
    wing_only = pitch_rad is None

    def state_of(z: np.ndarray) -> np.ndarray:
        theta = z[0] if wing_only else pitch_rad
        x = _base_state(af, altitude_m, airspeed_m_s, theta)
        x[dyn.N_RIGID + i_elev] = z[1]
        x[dyn.N_RIGID + n_lift:dyn.N_RIGID + n_rot] = z[2]
        if not wing_only:
            x[dyn.N_RIGID:dyn.N_RIGID + n_lift] = z[0] * dist
        return x

    def residual(z: np.ndarray) -> np.ndarray:
        return _accel(v, state_of(z))[[0, 2, 4]]  # north, down, pitch acceleration

    q_s = 0.5 * af.air_density_kg_m3 * airspeed_m_s**2 * af.wing.area_m2
    if wing_only:
        cl_need = af.weight_N / q_s
        z0 = np.array([(cl_need - af.wing.CL0) / af.wing.CL_alpha, 0.0, 0.3])
        lo, hi = [-0.5, -1.0, 0.0], [0.6, 1.0, 1.0]
    else:
        z0 = np.array([0.4, 0.0, 0.3])
        lo, hi = [0.0, -1.0, 0.0], [1.0, 1.0, 1.0]
    sol = least_squares(residual, z0, bounds=(lo, hi), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    # Polish with Newton on the square system (least_squares stops near machine precision).
    z = sol.x.copy()
    for _ in range(8):
        r = residual(z)
        if np.max(np.abs(r)) < 1e-12:
            break
        Jm = np.empty((3, 3))
        for j in range(3):
            zp = z.copy()
            zp[j] += 1e-7
            Jm[:, j] = (residual(zp) - r) / 1e-7
        try:
            z = z - np.linalg.solve(Jm, r)
        except np.linalg.LinAlgError:
            break
    res = float(np.max(np.abs(residual(z))))
    x = state_of(z)
    theta = z[0] if wing_only else float(pitch_rad)
    mode = "wing" if wing_only else "rotor-assisted"
    where = f"{mode} trim at {airspeed_m_s:g} m/s"
    if res > 1e-6:
        raise TrimError(f"{where}: no trim within the actuator limits (acceleration left "
                        f"{res:.3g}); the wing cannot carry the weight here" if wing_only else
                        f"{where}: no trim within the actuator limits (residual {res:.3g})")
    cmd = x[dyn.N_RIGID:].copy()
    if np.any(cmd[:n_rot] < -1e-9) or np.any(cmd[:n_rot] > 1 + 1e-9) or abs(z[1]) > 1 + 1e-9:
        raise TrimError(f"{where}: needs commands outside the limits: {np.round(cmd, 3)}")
    _, fm = v.derivatives(x, cmd)
    alpha = float(fm[7])
    cl, _ = dyn.lift_drag_coefficients(alpha, v.packed.P)
    if wing_only and alpha > (af.wing.CL_max - af.wing.CL0) / af.wing.CL_alpha + \
            0.5 * af.wing.stall_rounding_rad:
        raise TrimError(f"{where}: only a post-stall solution exists (alpha "
                        f"{math.degrees(alpha):.1f} deg)")
    rotor_force = float(np.sum(cmd[:n_lift] * [r.max_thrust_N for r in af.lift_rotors]))
    return TrimPoint(
        mode=mode, airspeed_m_s=airspeed_m_s, altitude_m=altitude_m, state=x, commands=cmd,
        pitch_rad=float(theta), alpha_rad=alpha,
        elevator_rad=float(z[1]) * af.surfaces.max_deflection_rad,
        pusher_thrust_fraction=float(z[2]), lift_rotor_fractions=cmd[:n_lift].copy(),
        lift_coefficient=float(cl), residual=res,
        rotor_lift_share=rotor_force * math.cos(theta) / af.weight_N,
    )


def trim_table(airframe: Airframe | None = None, airspeeds_m_s=(0.0, 4.0, 7.0, 10.0, 13.0, 18.0),
               altitude_m: float = 30.0, transition_pitch_rad: float = 0.0,
               ) -> list[tuple[float, str, TrimPoint | None, str]]:
    """Trim rows (airspeed, mode, point or None, note) for a report: hover at 0 m/s; at each
    airspeed the rotor-assisted transition trim (pitch ``transition_pitch_rad``, up to the
    stall speed) and the wing-borne trim where it exists."""
    af = airframe if airframe is not None else load_airframe()
    rows: list[tuple[float, str, TrimPoint | None, str]] = []
    v_stall = af.stall_speed_m_s()
    for V in airspeeds_m_s:
        if V == 0:
            rows.append((0.0, "hover", trim_hover(af, altitude_m), ""))
            continue
        if v_stall + 0.5 >= V:
            try:
                rows.append((V, "rotor-assisted",
                             trim_level_flight(af, V, altitude_m, transition_pitch_rad), ""))
            except TrimError as exc:
                rows.append((V, "rotor-assisted", None, str(exc)))
        if v_stall <= V:
            try:
                rows.append((V, "wing", trim_level_flight(af, V, altitude_m), ""))
            except TrimError as exc:
                rows.append((V, "wing", None, str(exc)))
        else:
            rows.append((V, "wing", None, f"below the stall speed ({v_stall:.1f} m/s)"))
    return rows
