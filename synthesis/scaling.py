"""Scales of the attitude design taken from the airframe's physics (no aircraft's numbers here).

Every number the design loop needs that depends on the aircraft comes from one of the
functions below, each a formula over the airframe file:

- :func:`actuator_bandwidth` omega_act = 1 / tau_act [rad/s], tau_act the slowest moment
  actuator's first-order time constant (lift rotors, surfaces): the frequency scale of the
  gain bounds (a gain bound with units 1/s is a multiple of omega_act, one with 1/s^2 a
  multiple of omega_act^2, a time bound a multiple of tau_act or of the control period).
- :func:`authority_bandwidth` omega_u = sqrt(u / (J r_max)) [rad/s]: the bandwidth at which a
  reference step r_max takes the moment u about an axis of inertia J (a bang-bang step of
  r_max in time ~ 2 / omega_u).
- :func:`transition_speeds` and :func:`scaled_design_points`: the design airspeeds from the
  airframe's transition range (hover .. transition end .. cruise), derived from the wing or
  declared.

The dimensionless ratios in the formulas are the paper's (table 1's points as fractions of
its transition end) or design rules with their meaning written beside them; for the reference
airframe DS-1 (50 ms actuators, 12.73 m/s clean stall) they reproduce, to the last bit, the
numbers the shipped gains were designed with (``tests/test_synthesis_scaling.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vtolftc.airframe.loader import (
    CRUISE_OVER_STALL,
    SPEED_GRID_M_S,
    Airframe,
    AirframeError,
    current_airspeeds,
    round_up_speed,
)
from vtolftc.synthesis.models import AXES, Axis
from vtolftc.synthesis.uncertainty import PAPER_DESIGN_POINTS, DesignPoint

__all__ = [
    "AUTOPILOT_PERIOD_S",
    "CRUISE_OVERSPEED_FRACTION",
    "CRUISE_OVER_STALL",
    "PAPER_TRANSITION_END_M_S",
    "SPEED_GRID_M_S",
    "TransitionSpeeds",
    "actuator_bandwidth",
    "actuator_time_constant",
    "authority_bandwidth",
    "axis_inertia",
    "require_authority",
    "require_bounds",
    "scaled_design_points",
    "transition_speeds",
]

#: The paper's transition end (its stall speed, table 1's last point) [m/s]: table 1's
#: airspeeds are used as fractions of it.
PAPER_TRANSITION_END_M_S = 13.0
#: The cruise point's perturbed range reaches above cruise by this fraction of the band
#: between transition end and cruise (speed-hold errors and gusts).
CRUISE_OVERSPEED_FRACTION = 0.4


def axis_inertia(af: Airframe, axis: Axis) -> float:
    """The principal moment of inertia J of ``axis`` [kg m^2] (FRD body axes).

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The attitude axis (Jx, Jy or Jz).

    Returns
    -------
    float
        J [kg m^2].
    """
    return float(np.diag(af.inertia_kg_m2)[AXES.index(axis)])


def actuator_time_constant(af: Airframe) -> float:
    """tau_act [s]: the slowest moment actuator's first-order time constant (lift rotors,
    surfaces; the pushers make no attitude moment).

    Parameters
    ----------
    af : Airframe
        The airframe (its lift rotors' and surfaces' time constants).

    Returns
    -------
    float
        tau_act [s], the largest of those time constants.

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> actuator_time_constant(load_airframe())     # DS-1: 50 ms actuators
    0.05
    """
    return float(max([r.time_constant_s for r in af.lift_rotors]
                     + [af.surfaces.time_constant_s]))


def actuator_bandwidth(af: Airframe) -> float:
    """omega_act = 1 / tau_act [rad/s] (:func:`actuator_time_constant`): the frequency scale
    of the gain bounds. A loop crossing over at omega_c loses atan(omega_c / omega_act) of
    phase to the actuator lag.

    Parameters
    ----------
    af : Airframe
        The airframe.

    Returns
    -------
    float
        omega_act [rad/s].

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> actuator_bandwidth(load_airframe())         # DS-1: 1 / 50 ms
    20.0
    """
    return 1.0 / actuator_time_constant(af)


def authority_bandwidth(u_max_N_m: float, inertia_kg_m2: float, r_max_rad: float) -> float:
    """omega_u = sqrt(u_max / (J r_max)) [rad/s]: the bandwidth at which a reference step
    ``r_max_rad`` [rad] takes the moment ``u_max_N_m`` [N m] about an axis of inertia
    ``inertia_kg_m2`` [kg m^2] (accelerating at u_max / J over half the step and braking over
    the other half takes 2 sqrt(r_max J / u_max) = 2 / omega_u). Doubling J or halving u_max
    divides it by sqrt(2).

    Parameters
    ----------
    u_max_N_m : float
        Moment authority u_max about the axis [N m], > 0.
    inertia_kg_m2 : float
        Moment of inertia J about the axis [kg m^2], > 0.
    r_max_rad : float
        Reference step r_max [rad], > 0.

    Returns
    -------
    float
        omega_u [rad/s].

    Examples
    --------
    >>> authority_bandwidth(8.0, 1.0, 2.0)          # sqrt(8 / (1 * 2))
    2.0
    >>> round(authority_bandwidth(8.0, 2.0, 2.0) * 2 ** 0.5, 12)   # twice J: / sqrt(2)
    2.0
    """
    return math.sqrt(u_max_N_m / (inertia_kg_m2 * r_max_rad))


def _who(af: Airframe) -> str:
    """``file.toml (name)``: how an error names the airframe."""
    return f"{Path(af.source).name} ({af.name})"


def require_authority(af: Airframe, axis: Axis, airspeed_m_s: float, u_max_N_m: float,
                      ) -> None:
    """Raise :class:`~vtolftc.airframe.loader.AirframeError` (one line, exit status 2 from
    the CLI) when the airframe has no moment about ``axis`` at ``airspeed_m_s``: no attitude
    loop can then be designed there.

    Parameters
    ----------
    af : Airframe
        The airframe (named in the error).
    axis : {"roll", "pitch", "yaw"}
        The attitude axis.
    airspeed_m_s : float
        The design point's airspeed [m/s] (named in the error).
    u_max_N_m : float
        The moment authority about ``axis`` there [N m].

    Raises
    ------
    AirframeError
        ``u_max_N_m`` is not finite and positive.
    """
    if not (math.isfinite(u_max_N_m) and u_max_N_m > 0.0):
        raise AirframeError(
            f"{_who(af)}: no {axis} moment authority at {airspeed_m_s:g} m/s (lift rotors and "
            f"surfaces give {u_max_N_m:g} N m): no {axis} attitude loop can be designed")


@dataclass(frozen=True)
class TransitionSpeeds:
    """The airspeeds that bound the design [m/s].

    Parameters
    ----------
    stall_m_s : float
        Clean-wing stall speed [m/s].
    transition_end_m_s : float
        Where the front transition completes: the last rotor-assisted design point [m/s].
    cruise_m_s : float
        The wing-borne design point [m/s].
    """

    stall_m_s: float
    transition_end_m_s: float
    cruise_m_s: float



def transition_speeds(af: Airframe, transition_end_m_s: float | None = None,
                      cruise_m_s: float | None = None) -> TransitionSpeeds:
    """The transition range of ``af``, declared or derived from the wing.

    The airframe's own :attr:`Airframe.airspeeds` (declared in its file or derived by the
    loader's rule: V_t = V_stall rounded up to :data:`SPEED_GRID_M_S`, V_c =
    :data:`CRUISE_OVER_STALL` V_stall rounded up, above V_t), unless overridden here.
    DS-1: V_stall 12.73, V_t 13, V_c 18 m/s (its design card's numbers).

    Parameters
    ----------
    af : Airframe
        The airframe (mass, wing area, CL_max, air density).
    transition_end_m_s : float, optional
        Declared transition end V_t [m/s]; default derived from the stall speed.
    cruise_m_s : float, optional
        Declared cruise speed V_c [m/s]; default derived from the stall speed.

    Returns
    -------
    TransitionSpeeds
        V_stall, V_t and V_c [m/s].

    Raises
    ------
    AirframeError
        A declared transition end below the stall or a cruise speed not above it.

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> sp = transition_speeds(load_airframe())
    >>> round(sp.stall_m_s, 2), sp.transition_end_m_s, sp.cruise_m_s
    (12.73, 13.0, 18.0)
    """
    own = current_airspeeds(af)
    vs = own.stall_m_s
    vt = own.transition_end_m_s if transition_end_m_s is None else float(transition_end_m_s)
    if cruise_m_s is not None:
        vc = float(cruise_m_s)
    elif transition_end_m_s is None:
        vc = own.cruise_m_s
    else:
        vc = max(round_up_speed(CRUISE_OVER_STALL * vs), vt + SPEED_GRID_M_S)
    if not vt > 0.0 or vt < vs - 1e-6:
        raise AirframeError(f"{_who(af)}: transition end {vt:g} m/s: expected at least the "
                            f"stall speed {vs:.2f} m/s")
    if not vc > vt:
        raise AirframeError(f"{_who(af)}: cruise {vc:g} m/s: expected above the transition "
                            f"end {vt:g} m/s")
    return TransitionSpeeds(vs, vt, vc)


def scaled_design_points(af: Airframe, *, cruise: bool,
                         speeds: TransitionSpeeds | None = None) -> tuple[DesignPoint, ...]:
    """The design points of ``af``: the paper's table 1 scaled to its transition range.

    Points 1-6 (nominal airspeed and perturbed range) are table 1's airspeeds times
    k = V_t / :data:`PAPER_TRANSITION_END_M_S` (the same fractions of the transition: hover,
    1/13, 4/13 ... of V_t). With ``cruise``, point 7 at V_c with the range [V_t, V_c +
    :data:`CRUISE_OVERSPEED_FRACTION` (V_c - V_t)] (the robust method's wing-borne point).
    For DS-1 (k = 1, V_c = 18): table 1's points and 18 m/s over 13-20 m/s.

    Parameters
    ----------
    af : Airframe
        The airframe.
    cruise : bool
        Append the wing-borne cruise point (the robust method's point 7).
    speeds : TransitionSpeeds, optional
        The transition range; default :func:`transition_speeds` ``(af)``.

    Returns
    -------
    tuple of DesignPoint
        Six points (seven with ``cruise``), numbered from 1; airspeeds in m/s.

    Raises
    ------
    AirframeError
        Through :func:`transition_speeds` when ``speeds`` is not given.

    Examples
    --------
    >>> from vtolftc.airframe.loader import load_airframe
    >>> pts = scaled_design_points(load_airframe(), cruise=True)
    >>> [p.airspeed_m_s for p in pts]
    [0.0, 1.0, 4.0, 7.0, 10.0, 13.0, 18.0]
    >>> pts[-1].v_min_m_s, pts[-1].v_max_m_s
    (13.0, 20.0)
    """
    sp = transition_speeds(af) if speeds is None else speeds
    vt = sp.transition_end_m_s

    def k(v: float) -> float:  # v V_t / 13 m/s (the last point ends at V_t exactly)
        return v * vt / PAPER_TRANSITION_END_M_S

    pts = tuple(DesignPoint(p.number, k(p.airspeed_m_s), k(p.v_min_m_s), k(p.v_max_m_s))
                for p in PAPER_DESIGN_POINTS)
    if not cruise:
        return pts
    vc = sp.cruise_m_s
    return (*pts, DesignPoint(len(pts) + 1, vc, vt, vc + CRUISE_OVERSPEED_FRACTION * (vc - vt)))


#: The autopilot's control period [s] (250 Hz): the time scale of the derivative filter's
#: bounds (a filter faster than 2.5 periods would act near the Nyquist frequency).
AUTOPILOT_PERIOD_S = 0.004


def require_bounds(af: Airframe, axis: Axis, bounds: dict[str, tuple[float, float]]) -> None:
    """Raise :class:`~vtolftc.airframe.loader.AirframeError` (one line) if a gain's lower
    bound ``bounds[name][0]`` is not below its upper bound: the airframe's physics leave no
    room for that gain of the ``axis`` loop.

    Parameters
    ----------
    af : Airframe
        The airframe (named in the error).
    axis : {"roll", "pitch", "yaw"}
        The attitude axis whose loop the gains belong to.
    bounds : dict of str to (float, float)
        Gain name -> (lower, upper) bound, in the gain's own units.

    Raises
    ------
    AirframeError
        A bound is not finite, or a lower bound is not below its upper bound.
    """
    for name, (lo, hi) in bounds.items():
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise AirframeError(
                f"{_who(af)}: the {axis} loop's {name} has no admissible value (bounds "
                f"[{lo:g}, {hi:g}] from its authority, inertia and actuator bandwidth): no "
                f"{axis} attitude loop can be designed")
