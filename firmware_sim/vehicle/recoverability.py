"""The physical recoverability oracle: can the actuators left after a fault hold the trim?

For a fault set at a flight condition (airspeed, pitch, wind) the question is whether the
remaining actuators, within their position limits and with the failed ones at their failed
values, can produce the force and moments the trim needs, and with how much to spare. It is
a property of the airframe's physics, not of any controller: the limit of passive fault
tolerance, against which a campaign's survival is judged.

The wrench model
----------------
At a fixed rigid-body state (attitude, velocity, zero body rates, wind) the vehicle's
non-gravitational body force and moment (:func:`vtolftc.firmware_sim.vehicle.dynamics.derivatives`,
FRD body axes, N and N m) are affine in the actuator positions: rotor thrust is
``eff * T_max * u * fade(inflow)``, every control-surface term is linear in its deflection
(lift, side force, the three moments) and drag does not depend on the deflections. So
``w(u) = w0 + B u`` exactly, with ``w0`` the wrench at zero commands (aerodynamics of the
clean airframe, plus gravity rotated into the body) and ``B`` (6 x n) the actuator
effectiveness, read from the model itself by unit steps (:func:`wrench_model`). Any airframe
file works: the actuators, their limits and their order are the airframe's.

Faults (``(actuator, kind, loss)`` as :class:`~vtolftc.firmware_sim.vehicle.faults.Fault`):
``off`` zeroes the actuator's column (it still has a position, which does nothing); ``loss``
scales its column by ``1 - loss``; ``stuck`` fixes its position at the condition's actuator
position (the value it had when the fault struck). Faults on one actuator compose as in the
vehicle.

The demand
----------
The trim to hold at the condition (gravity included, FRD body axes): the forward force ``Fx``
and the vertical force ``Fz`` (N) and the moments ``L``, ``M``, ``N`` (N m) sum to zero. The
side force ``Fy`` is free: a vehicle that cannot balance it drifts sideways with the air
mass, which neither its attitude nor its altitude minds. Besides the commands, the trim may
change the pitch and the roll attitude by at most ``tilt_max`` (default 10 deg, PX4's
``MPC_TILTMAX_AIR`` of the flight software) from the condition's, at the same velocity
over the ground (linearised: ``G``, the wrench's slope in pitch and roll, read from the
model as the secant over +-5 deg; a secant, not a tangent, because the model's moments jump
where the angle of attack wraps at 180 deg, in hover with a tailwind): the weight then
balances a forward force (the vehicle leans into it), and in wing-borne flight a pitch
change is an angle of attack change, which is how a wing makes its vertical force. So the
weight is carried by the rotors in hover, by the wing and the rotors in a transition and by
the wing in cruise, whatever the condition's state makes of it.

Wind: the condition's wind (NED, m/s) enters the air-relative velocity of the state, so its
drag, side force and sideslip moments (C_lbeta, C_nbeta) are part of ``w0``, i.e. of the
demand: give it the wind *relative to the vehicle's steady motion* (a hovering vehicle that
holds its position feels the whole wind; one in forward flight drifts with the air mass and
feels only a gust). A gust is one more condition (that wind plus the gust's peak, the
1 - cosine gust's amplitude): :func:`assess` takes the smallest margin of them. Not modelled:
the rate and acceleration terms of a gust (a quasi-steady demand only).

The margin (rad/s^2)
--------------------
With ``J_xx, J_yy, J_zz`` the principal inertias and ``m`` the mass of the physical vehicle:

- **margin >= 0**: the largest ``a`` such that, at the trim's attitude, every corner of the
  moment box ``[L, M, N]_trim + a (+-J_xx, +-J_yy, +-J_zz)`` can be produced, each by its
  own admissible commands, with each demanded force component (``Fx``, ``Fz``) off its
  balance by at most ``a m`` (a transient of at most ``a`` m/s^2). In words: with the trim
  held, the vehicle can still accelerate about every body axis by ``a`` rad/s^2, in both
  directions and all combinations at once, without losing more than ``a`` m/s^2 of any
  force balance. Zero
  means the trim exists but some direction has no authority left.
- **margin < 0**: no trim exists within ``tilt_max``; ``-a`` is the smallest ``e`` such that
  every demanded wrench component is met to within ``e`` times its scale (``m`` for the
  forces, the inertias for the moments): the uniform acceleration deficit (m/s^2 and rad/s^2) the
  fault leaves. ``-inf``: not even that LP could be solved.

The verdict ``recoverable`` is ``margin >= RECOVERABLE_MIN_MARGIN`` = 0.001 rad/s^2: a trim
exists and every direction keeps some authority. The threshold only keeps a degenerate box
(an LP answer of 0 +- 1e-9) out; it claims nothing about how much reserve a controller
needs (0.001 rad/s^2 would take 45 s to turn the vehicle by 1 rad): the margin itself is in
the answer for a stricter reading. Each margin is one linear program (scipy's HiGHS), a
second one when the trim does not exist: :func:`recovery_margin`.

The thrust reserve of the campaign notes (``docs/campaigns/hover_margin.py``) lives here too:
:func:`thrust_reserve`, the largest upward force with the moments held at zero.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from itertools import product

import numpy as np
from scipy.optimize import linprog

from vtolftc.airframe.loader import Airframe
from vtolftc.base.rotation import euler_to_quat
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.faults import Fault, FaultError, FaultKind
from vtolftc.firmware_sim.vehicle.model import Perturbation, Vehicle

__all__ = [
    "AXES",
    "DEFAULT_TILT_MAX_RAD",
    "DEMAND",
    "RECOVERABLE_MIN_MARGIN",
    "FlightCondition",
    "Recoverability",
    "WrenchModel",
    "assess",
    "recovery_margin",
    "thrust_reserve",
    "trim_condition",
    "wrench_model",
]

#: Body wrench components, FRD: forces (N) then moments about the CG (N m).
AXES = ("Fx", "Fy", "Fz", "L", "M", "N")
#: Tilt of the attitude allowed to balance a horizontal force (rad).
DEFAULT_TILT_MAX_RAD = math.radians(10.0)
#: Smallest margin (rad/s^2) called recoverable (see the module docstring).
RECOVERABLE_MIN_MARGIN = 1e-3
#: The wrench axes a trim must balance by default (the side force is free: drift).
DEMAND = ("Fx", "Fz", "L", "M", "N")
_ATTITUDE_STEP_RAD = math.radians(5.0)


@dataclass(frozen=True)
class FlightCondition:
    """Where the oracle is evaluated: the vehicle flies level, heading north, wings level.

    Parameters
    ----------
    mode : str
        A label (``hover``, ``rotor-assisted``, ``wing`` or a phase name); the physics comes
        from the other fields only.
    speed_m_s : float
        Velocity over the ground along north = body x (m/s); in calm air the airspeed.
    pitch_rad : float
        Pitch attitude (rad).
    wind_ned_m_s : tuple of float
        Wind (NED, m/s): the air moves with it, so the air-relative velocity is
        ``(speed, 0, 0) - wind`` in NED.
    actuator_positions : tuple of float or None
        Normalised actuator positions at the fault (airframe order): where a stuck actuator
        stays. None: all zero.
    """

    mode: str
    speed_m_s: float
    pitch_rad: float = 0.0
    wind_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    actuator_positions: tuple[float, ...] | None = None

    def with_wind(self, wind_ned_m_s: Sequence[float]) -> FlightCondition:
        """The same condition in another wind (NED, m/s)."""
        w = tuple(float(v) for v in wind_ned_m_s)
        return FlightCondition(self.mode, self.speed_m_s, self.pitch_rad,
                               (w[0], w[1], w[2]), self.actuator_positions)


@dataclass(frozen=True)
class WrenchModel:
    """``w(u) = w0 + B u``: the body wrench (FRD; N, N m) as a function of the commands.

    ``w0`` includes gravity (body axes) and the clean airframe's aerodynamics at the
    condition; ``B[:, i]`` is actuator ``i``'s wrench per unit of normalised command;
    ``lower`` / ``upper`` its position limits; ``scale`` the mass (kg, force rows) and
    principal inertias (kg m^2, moment rows) that turn the wrench into accelerations.
    """

    names: tuple[str, ...]
    B: np.ndarray
    w0: np.ndarray
    G: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    weight_N: float
    condition: FlightCondition

    def wrench(self, commands: np.ndarray) -> np.ndarray:
        """The wrench (6,) at the given commands (healthy actuators)."""
        return self.w0 + self.B @ np.asarray(commands, dtype=float)


@dataclass(frozen=True)
class Recoverability:
    """The oracle's answer for one fault set at one condition.

    ``margin`` in 1/s^2 (see the module docstring: >= 0 the reserve box, < 0 the deficit;
    -inf when the LP could not be solved); ``recoverable`` = ``margin >= threshold``;
    ``commands`` a set of admissible commands that holds the trim (None when none exists).
    """

    margin: float
    recoverable: bool
    threshold: float
    commands: np.ndarray | None = field(default=None, repr=False)
    attitude_change_rad: np.ndarray | None = field(default=None, repr=False)


def _state(af: Airframe, cond: FlightCondition, roll_rad: float = 0.0,
           pitch_offset_rad: float = 0.0, altitude_m: float = 30.0) -> np.ndarray:
    x = np.zeros(dyn.N_RIGID + af.n_actuators)
    x[2] = -altitude_m
    x[3] = float(cond.speed_m_s)
    x[6:10] = euler_to_quat(roll_rad, float(cond.pitch_rad) + pitch_offset_rad, 0.0)
    return x


def wrench_model(af: Airframe, cond: FlightCondition,
                 perturbation: Perturbation | None = None) -> WrenchModel:
    """The affine wrench model of the (perturbed) vehicle at ``cond`` (see the module doc).

    Read from the vehicle's own equations of motion: ``w0`` at zero commands, ``B`` by a unit
    step of each actuator (exact: the wrench is affine in the positions at a fixed state),
    ``G`` as the secant in pitch and roll over +-5 deg (at the condition's actuator
    positions, the velocity over the ground held).
    """
    wind = tuple(float(v) for v in cond.wind_ned_m_s)
    veh = Vehicle(af, wind_ned_m_s=wind, perturbation=perturbation)
    n = af.n_actuators
    pk = veh.packed
    mass = float(pk.P[dyn.P_MASS])
    weight = mass * float(pk.P[dyn.P_G])

    def wrench_at(u: np.ndarray, roll: float = 0.0, dpitch: float = 0.0) -> np.ndarray:
        xs = _state(af, cond, roll, dpitch)
        xs[dyn.N_RIGID:] = u
        _, fm = veh.derivatives(xs, u)
        R = dyn_rotation(xs[6:10])
        return np.concatenate([fm[0:3] + R.T @ np.array([0.0, 0.0, weight]), fm[3:6]])

    w0 = wrench_at(np.zeros(n))
    B = np.empty((6, n))
    for i in range(n):
        e = np.zeros(n)
        e[i] = 1.0
        B[:, i] = wrench_at(e) - w0
    u_ref = (np.zeros(n) if cond.actuator_positions is None
             else np.asarray(cond.actuator_positions, dtype=float))
    if u_ref.shape != (n,):
        raise ValueError(f"actuator_positions of shape {u_ref.shape}: expected ({n},) in the "
                         f"order {', '.join(af.actuator_names)}")
    h = _ATTITUDE_STEP_RAD
    G = np.stack([(wrench_at(u_ref, 0.0, h) - wrench_at(u_ref, 0.0, -h)) / (2 * h),
                  (wrench_at(u_ref, h) - wrench_at(u_ref, -h)) / (2 * h)], axis=1)
    J = pk.J
    scale = np.array([mass, mass, mass, J[0, 0], J[1, 1], J[2, 2]])
    return WrenchModel(tuple(af.actuator_names), B, w0, G, pk.act_min.copy(),
                       pk.act_max.copy(), scale, weight, cond)


def dyn_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrix body FRD -> NED of a unit quaternion (w, x, y, z)."""
    R = np.empty((3, 3))
    dyn.quat_to_dcm(float(q[0]), float(q[1]), float(q[2]), float(q[3]), R)
    return R


def _faulted(model: WrenchModel, faults: Iterable[Fault | tuple[str, str, float]],
             hold: Iterable[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(B with the faults' effectiveness, lower, upper bounds with stuck / held actuators
    fixed at the condition's positions)."""
    B = model.B.copy()
    lo = model.lower.copy()
    hi = model.upper.copy()
    pos = (np.zeros(len(model.names)) if model.condition.actuator_positions is None
           else np.asarray(model.condition.actuator_positions, dtype=float))
    for f in faults:
        flt = f if isinstance(f, Fault) else Fault(f[0], FaultKind(f[1]), float(f[2]))
        if flt.actuator not in model.names:
            raise FaultError(f"unknown actuator {flt.actuator!r}; this airframe has: "
                             f"{', '.join(model.names)}")
        i = model.names.index(flt.actuator)
        B[:, i] *= flt.effectiveness
        if flt.kind is FaultKind.STUCK:
            lo[i] = hi[i] = min(model.upper[i], max(model.lower[i], pos[i]))
    for name in hold:
        if name not in model.names:
            raise FaultError(f"unknown actuator {name!r} to hold; this airframe has: "
                             f"{', '.join(model.names)}")
        i = model.names.index(name)
        lo[i] = hi[i] = min(model.upper[i], max(model.lower[i], pos[i]))
    return B, lo, hi


def recovery_margin(model: WrenchModel, faults: Iterable[Fault | tuple[str, str, float]] = (),
                    *, demand: Sequence[str] = DEMAND,
                    tilt_max_rad: float = DEFAULT_TILT_MAX_RAD, hold: Iterable[str] = (),
                    threshold: float = RECOVERABLE_MIN_MARGIN) -> Recoverability:
    """The recovery margin of ``faults`` at the model's condition (one or two LPs).

    Parameters
    ----------
    model : WrenchModel
        From :func:`wrench_model`.
    faults : iterable of Fault or (actuator, kind, loss)
        The fault set (kinds ``off``, ``stuck``, ``loss``).
    demand : sequence of str
        The wrench axes that must balance (subset of :data:`AXES`, default :data:`DEMAND`);
        the others are free. The box of the margin spans the moment axes among them.
    tilt_max_rad : float
        Largest change of pitch and of roll from the condition's attitude (rad).
    hold : iterable of str
        Actuators held at the condition's positions (not used by the flight software there).
    threshold : float
        Smallest margin called recoverable (rad/s^2).

    Returns
    -------
    Recoverability
        margin (rad/s^2), verdict, the commands and attitude change of the trim.
    """
    for a in demand:
        if a not in AXES:
            raise ValueError(f"demand axis {a!r}: expected some of {', '.join(AXES)}")
    B, lo, hi = _faulted(model, faults, hold)
    n = B.shape[1]
    eq = [AXES.index(a) for a in AXES if a in demand]
    box = [k for k in eq if k >= 3]
    S = model.scale
    G = model.G
    forces = [k for k in eq if k < 3]
    corners = list(product((-1.0, 1.0), repeat=len(box)))
    nc = len(corners)
    # variables: the trim's commands u_0, the commands u_c of every corner of the box, the
    # attitude change (pitch, roll; the trim's, shared by the corners), then a (rad/s^2)
    nu = (nc + 1) * n
    nv = nu + 3
    att = slice(nu, nu + 2)
    A_eq = np.zeros((len(eq) + nc * len(box), nv))
    b_eq = np.zeros(A_eq.shape[0])
    A_ub = np.zeros((2 * nc * len(forces), nv))
    b_ub = np.zeros(A_ub.shape[0])
    r = 0
    for k in eq:  # the trim: every demanded axis balances
        A_eq[r, 0:n] = B[k]
        A_eq[r, att] = G[k]
        b_eq[r] = -model.w0[k]
        r += 1
    ru = 0
    for c, signs in enumerate(corners, start=1):
        cols = slice(c * n, (c + 1) * n)
        for k, sg in zip(box, signs, strict=True):  # the corner's moment, exactly
            A_eq[r, cols] = B[k]
            A_eq[r, att] = G[k]
            A_eq[r, -1] = -sg * S[k]
            b_eq[r] = -model.w0[k]
            r += 1
        for k in forces:  # its force transient within a (m/s^2) on every demanded axis
            for sg in (1.0, -1.0):
                A_ub[ru, cols] = sg * B[k]
                A_ub[ru, att] = sg * G[k]
                A_ub[ru, -1] = -S[k]
                b_ub[ru] = -sg * model.w0[k]
                ru += 1
    tilt = (-tilt_max_rad, tilt_max_rad)
    bounds = [(lo[i % n], hi[i % n]) for i in range(nu)] + [tilt, tilt] + [(0.0, None)]
    cost = np.zeros(nv)
    cost[-1] = -1.0
    res = linprog(cost, A_ub=A_ub if ru else None, b_ub=b_ub if ru else None, A_eq=A_eq,
                  b_eq=b_eq, bounds=bounds, method="highs")
    if res.status == 0:
        a = float(res.x[-1])
        return Recoverability(a, a >= threshold, threshold, res.x[0:n].copy(),
                              res.x[att].copy())
    # infeasible: the smallest uniform deficit e with |residual_k| <= e S_k on every axis
    nv = n + 3
    rows, rhs = [], []
    for k in eq:
        for sg in (1.0, -1.0):
            row = np.zeros(nv)
            row[:n] = sg * B[k]
            row[n:n + 2] = sg * G[k]
            row[-1] = -S[k]
            rows.append(row)
            rhs.append(-sg * model.w0[k])
    cost = np.zeros(nv)
    cost[-1] = 1.0
    res2 = linprog(cost, A_ub=np.array(rows), b_ub=np.array(rhs),
                   bounds=[(lo[i], hi[i]) for i in range(n)] + [tilt, tilt] + [(0.0, None)],
                   method="highs")
    if res2.status != 0:
        return Recoverability(-math.inf, False, threshold)
    e = float(res2.x[-1])
    return Recoverability(-e, -e >= threshold, threshold)


def thrust_reserve(model: WrenchModel, faults: Iterable[Fault | tuple[str, str, float]] = (),
                   *, balanced: Sequence[str] = ("L", "M"), use: Iterable[str] | None = None,
                   ) -> float:
    """The largest upward force (-Fz of the actuators and aerodynamics, N) with the moments
    ``balanced`` held at zero, over the weight (dimensionless); 0 when none exists.

    ``use``: the actuators that may move (default all); the others stay at the condition's
    positions. Gravity is not counted in the force (it is the denominator). This is the
    moment-balanced thrust margin of ``docs/campaigns/hover_margin.py``.
    """
    names = set(model.names if use is None else use)
    hold = [a for a in model.names if a not in names]
    B, lo, hi = _faulted(model, faults, hold)
    rows = [AXES.index(a) for a in balanced]
    g_free_w0 = model.w0.copy()
    R = dyn_rotation(euler_to_quat(0.0, float(model.condition.pitch_rad), 0.0))
    g_free_w0[0:3] -= R.T @ np.array([0.0, 0.0, model.weight_N])
    res = linprog(B[2], A_eq=B[rows] if rows else None,
                  b_eq=-model.w0[rows] if rows else None,
                  bounds=list(zip(lo, hi, strict=True)), method="highs")
    if res.status != 0:
        return 0.0
    return max(0.0, float(-(g_free_w0[2] + res.fun) / model.weight_N))  # never -0.0


def trim_condition(af: Airframe, mode: str, airspeed_m_s: float = 0.0,
                   wind_ned_m_s: Sequence[float] = (0.0, 0.0, 0.0),
                   transition_pitch_rad: float = 0.0) -> FlightCondition:
    """The condition of a nominal trim: ``hover`` (rotors carry the weight),
    ``rotor-assisted`` (pitch ``transition_pitch_rad``, the wing's lift at the airspeed plus
    the rotors: a mid-transition) or ``wing`` (wing-borne cruise), with the trim's commands
    as the actuator positions (where a stuck actuator stays). Raises
    :class:`~vtolftc.firmware_sim.vehicle.trim.TrimError` when the trim does not exist."""
    from vtolftc.firmware_sim.vehicle.trim import trim_hover, trim_level_flight

    if mode == "hover":
        tp = trim_hover(af)
        speed = 0.0
    elif mode == "rotor-assisted":
        tp = trim_level_flight(af, airspeed_m_s, pitch_rad=transition_pitch_rad)
        speed = airspeed_m_s
    elif mode == "wing":
        tp = trim_level_flight(af, airspeed_m_s)
        speed = airspeed_m_s
    else:
        raise ValueError(f"mode {mode!r}: expected hover, rotor-assisted or wing")
    w = tuple(float(v) for v in wind_ned_m_s)
    return FlightCondition(mode, speed, float(tp.pitch_rad), (w[0], w[1], w[2]),
                           tuple(float(v) for v in tp.commands))


def assess(af: Airframe, faults: Iterable[Fault | tuple[str, str, float]],
           cond: FlightCondition, *, gust_peaks_ned_m_s: Iterable[Sequence[float]] = (),
           perturbation: Perturbation | None = None, hold: Iterable[str] = (),
           demand: Sequence[str] = DEMAND, tilt_max_rad: float = DEFAULT_TILT_MAX_RAD,
           threshold: float = RECOVERABLE_MIN_MARGIN,
           model_cache: dict[tuple[object, ...], WrenchModel] | None = None) -> Recoverability:
    """:func:`recovery_margin` at ``cond`` and, for each gust, at the steady wind plus the
    gust's peak (amplitude, NED, m/s): the smallest margin of them. ``model_cache`` (a dict)
    keeps the wrench models between calls on the same airframe (they do not depend on the
    faults)."""
    faults = list(faults)
    hold = list(hold)
    winds = [np.asarray(cond.wind_ned_m_s, float)]
    winds += [winds[0] + np.asarray(g, float) for g in gust_peaks_ned_m_s
              if any(float(v) != 0.0 for v in g)]
    out: Recoverability | None = None
    for w in winds:
        c = cond.with_wind(w)
        key = (c, perturbation)
        model = None if model_cache is None else model_cache.get(key)
        if model is None:
            model = wrench_model(af, c, perturbation)
            if model_cache is not None:
                model_cache[key] = model
        r = recovery_margin(model, faults,
                            demand=demand, tilt_max_rad=tilt_max_rad, hold=hold,
                            threshold=threshold)
        if out is None or r.margin < out.margin:
            out = r
    assert out is not None
    return out
