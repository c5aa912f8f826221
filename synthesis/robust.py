"""The robust attitude design (``vtolftc synth --method robust``, the default), for DS-1
and any airframe of its class (every scale from the airframe file: :mod:`.scaling`).

The method stays the paper's: structured H-infinity mixed sensitivity of the fixed P-PID
cascade (fig. 5) at airspeed design points, faults as multiplicative input uncertainty, mu
analysis, gains scheduled by airspeed, the controller never told which actuator failed. What
changes is how the problem is posed for the aircraft that flies it. Per axis and design point:

a. **Input-disturbance objective.** Losing a lift rotor is more than a loss of effectiveness:
   the rotor's trim thrust leaves a moment at the plant input. :func:`rotor_out_moment` is the
   largest such moment over the lift rotors at the point's airspeed (trim thrusts from the
   airframe file: weight minus the wing's lift at zero pitch, shared by the rotors with zero
   moment, min-norm). The channel ``||Wd e/d||_inf <= 1`` with the constant
   ``Wd = d_max / e_max`` (``e_max`` = :data:`EXCURSION_RAD`, 15 deg declared, designed with
   the margin :data:`EXCURSION_DESIGN_FACTOR`) bounds the angle response to that moment, and
   below omega_b the weight rises as 1/w so the error must also recover at the tracking
   bandwidth (:func:`disturbance_weight`); the linear step response
   (:func:`disturbance_peak`) is reported next to it.
b. **Loop delays in the design plant.** :func:`design_plant` = eq. 1-3 model x first-order
   actuator lag (the airframe's actuator time constant) with the loop's transport delay
   (:class:`LoopDelays`: 1.5 control periods of sample-hold and computation plus the declared
   HIL transport) folded into it. Requirement: stable with at least
   :attr:`LoopDelays.extra_margin_s` (50 ms) more loop delay at every point, designed as
   ``||W_delta T_u||_inf <= 1`` (small gain; ``W_delta`` covers ``|exp(-j w tau) - 1|`` for
   every tau up to the margin, :func:`delay_weight`), checked exactly in frequency
   (:func:`loop_margins`: delay margin and disk margin).
c. **Nominal at the set's centre.** :func:`vtolftc.synthesis.uncertainty.centred_nominal`
   picks the member (airspeed, gamma) about which the multiplicative cover is smallest; the
   cover is refitted about it and the design plant built there.
d. **Ws by rule** (:func:`sensitivity_rule`): omega_b = min(omega_act / 8, omega_u / 2), with
   omega_act = 1 / tau_act the actuator bandwidth (rate loop at most omega_act / 2 so the lag
   costs < 27 deg at crossover, outer loop a quarter of that) and omega_u =
   sqrt((u_max - d_max) / (J r_max)) the bandwidth at which a reference step r_max takes the
   authority left after the worst rotor-out; M = the sensitivity peak of the second-order loop
   whose step overshoot is :data:`OVERSHOOT` (20 %). Table 2's values are printed beside.
e. **Design points from the transition range** (:func:`robust_points`): the paper's six
   scaled to the airframe's transition end V_t (table 1's airspeeds times V_t / 13 m/s) and
f. **a cruise point** V_c over [V_t, V_c + 0.4 (V_c - V_t)] (DS-1: 18 m/s over 13-20 m/s;
   V_t and V_c from the wing or declared, :func:`~vtolftc.synthesis.scaling.
   transition_speeds`), so the schedule covers the envelope flown; in fixed-wing the
   allocator keeps the lift rotors as a reserve (autopilot).
g. **Gain bounds from physics** (:func:`robust_parameters`): outer loop <= omega_act / 2;
   rate-loop crossover kp_rate / J <= omega_act; the controller's high-frequency gain
   kp_rate + kd_rate / tf_rate_s bounded by gyro noise (3 sigma of
   :data:`GYRO_NOISE_RAD_S` must not cost more than 5 % of u_max, nor slew the moment faster
   than the actuators' rate limit allows in one control period); each of kp_rate and
   kd_rate / tf_min is held below that bound; the other bounds and the start are multiples
   of omega_act, omega_act^2, tau_act or the control period (formulas in
   :func:`robust_parameters`; DS-1's former numbers exactly). Every active bound is
   reported. An axis without authority is refused (``AirframeError``, one line).

Channels (all minimised together, minimax, :func:`vtolftc.synthesis.structured.tune`): eq. 8
``[Ws S; Wt T_u; Wr R]`` normalised by its own floor ``max(1, |Wt(0)|)`` (with integral action
T_u(0) = 1, so no controller gets below |Wt(0)|; without the normalisation that floor would
mask the other requirements at hover points), ``Wd e/d`` and ``W_delta T_u``, all on the
design plant at the centred nominal. The reported norms and the mu analysis are unnormalised.

SHIF gets the same channels at every point with one constant controller; LQR stays the
paper's (:mod:`vtolftc.synthesis.baselines`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import control as ct
import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe, load_airframe
from vtolftc.synthesis.design import (
    A_SENSITIVITY,
    OMEGA_A_RAD_S,
    R_MAX_RAD,
    TABLE2,
    AxisWeights,
)
from vtolftc.synthesis.design_loop import (
    SHIF_TAG,
    AxisDesign,
    TuningSetup,
    achieved_norms,
    pick_start,
    point_seed,
    run_design_loop,
    tune_axis,
)
from vtolftc.synthesis.hinfnorm import StateSpaceData, as_state_space, frequency_response
from vtolftc.synthesis.loops import (
    PARAM_NAMES,
    CascadeChannel,
    ControlWeight,
    SensitivityWeight,
    closed_loop,
    rate_controller,
)
from vtolftc.synthesis.models import Axis, attitude_model
from vtolftc.synthesis.scaling import (
    AUTOPILOT_PERIOD_S,
    actuator_bandwidth,
    actuator_time_constant,
    authority_bandwidth,
    axis_inertia,
    require_authority,
    require_bounds,
    scaled_design_points,
)
from vtolftc.synthesis.structured import Parameter, TuneResult, TuningProblem
from vtolftc.synthesis.uncertainty import DesignPoint, centred_nominal, cover

__all__ = [
    "EXCURSION_RAD",
    "GYRO_NOISE_RAD_S",
    "OVERSHOOT",
    "ROBUST_DESIGN_POINTS",
    "LoopDelays",
    "LoopMargins",
    "RobustMethod",
    "RobustSpec",
    "delay_weight",
    "design_plant",
    "disturbance_peak",
    "loop_margins",
    "moment_authority_robust",
    "robust_parameters",
    "robust_points",
    "robust_weights",
    "rotor_out_moment",
    "run_robust_designs",
    "sensitivity_rule",
    "trim_rotor_thrusts",
]



def robust_points(af: Airframe) -> tuple[DesignPoint, ...]:
    """The robust method's design points for ``af``: the paper's six scaled to its
    transition range plus the wing-borne cruise point V_c over [V_t, V_c + 0.4 (V_c - V_t)]
    (:func:`~vtolftc.synthesis.scaling.scaled_design_points`)."""
    return scaled_design_points(af, cruise=True)


#: DS-1's points (the shipped airframe): the paper's six plus the wing-borne cruise point
#: (18 m/s, range 13-20 m/s), :func:`robust_points` of ``airframe/ds1.toml``.
ROBUST_DESIGN_POINTS: tuple[DesignPoint, ...] = robust_points(load_airframe(None))
#: Declared worst single rotor-out angle excursion [rad] (15 deg).
EXCURSION_RAD = math.radians(15.0)
#: The H-infinity bound on e/d is a frequency-domain proxy of the step peak; designing for
#: e_max / 1.25 keeps the step response within e_max for loops damped as these are.
EXCURSION_DESIGN_FACTOR = 1.25
#: Step overshoot bound of the tracking loop (for the rule of M).
OVERSHOOT = 0.20
#: Gyro noise, one sigma [rad/s] (the sensor model's realistic option).
GYRO_NOISE_RAD_S = 0.004


@dataclass(frozen=True)
class LoopDelays:
    """Delays of the real loop [s]: control period (sample-hold + one period of computation
    and output: 1.5 periods of delay), declared HIL transport (one-way state + command, as
    the design assumes it), and the extra loop delay the design must tolerate."""

    control_period_s: float = AUTOPILOT_PERIOD_S
    hil_transport_s: float = 0.002
    extra_margin_s: float = 0.050

    @property
    def transport_s(self) -> float:
        """Modelled pure delay in the design plant [s]."""
        return 1.5 * self.control_period_s + self.hil_transport_s


@dataclass(frozen=True)
class RobustSpec:
    """Settings of the robust design (defaults: DS-1's declared requirements)."""

    delays: LoopDelays = LoopDelays()
    excursion_rad: float = EXCURSION_RAD
    overshoot: float = OVERSHOOT
    gyro_noise_rad_s: float = GYRO_NOISE_RAD_S

    def to_dict(self) -> dict[str, float]:
        """Delays (s), excursion (rad), overshoot and gyro noise (rad/s) as a JSON-ready dict."""
        return {"control_period_s": self.delays.control_period_s,
                "hil_transport_s": self.delays.hil_transport_s,
                "modelled_transport_delay_s": self.delays.transport_s,
                "extra_delay_margin_s": self.delays.extra_margin_s,
                "excursion_rad": self.excursion_rad,
                "excursion_design_factor": EXCURSION_DESIGN_FACTOR,
                "overshoot": self.overshoot, "gyro_noise_rad_s": self.gyro_noise_rad_s}


# ------------------------------------------------------------------------------------------
# physics from the airframe file
# ------------------------------------------------------------------------------------------


def trim_rotor_thrusts(af: Airframe, airspeed_m_s: float) -> NDArray[np.float64]:
    """Lift-rotor trim thrusts [N] at ``airspeed_m_s`` in level flight at zero pitch (the
    transition attitude): total = weight - wing lift (qbar S CL0, >= 0), no roll or pitch
    moment, min-norm share (the allocator's preference for equal thrusts)."""
    w = af.wing
    qbar = 0.5 * af.air_density_kg_m3 * airspeed_m_s**2
    total = max(0.0, af.weight_N - qbar * w.area_m2 * w.CL0)
    x = np.array([float(r.position_m[0]) for r in af.lift_rotors])
    y = np.array([float(r.position_m[1]) for r in af.lift_rotors])
    A = np.vstack([np.ones_like(x), x, y])
    T, *_ = np.linalg.lstsq(A, np.array([total, 0.0, 0.0]), rcond=None)
    return np.asarray(T, float)


def rotor_out_moment(af: Airframe, axis: Axis, airspeed_m_s: float) -> float:
    """Largest trim moment [N m] about ``axis`` that switching one lift rotor off leaves
    (its trim thrust times its arm; yaw: its reaction torque)."""
    T = trim_rotor_thrusts(af, airspeed_m_s)
    out = 0.0
    for r, t in zip(af.lift_rotors, T, strict=True):
        arm = {"roll": abs(float(r.position_m[1])), "pitch": abs(float(r.position_m[0])),
               "yaw": r.torque_to_thrust_m}[axis]
        out = max(out, arm * float(t))
    return out


def moment_authority_robust(af: Airframe, axis: Axis, airspeed_m_s: float) -> float:
    """u_max [N m] for the robust design: the lift rotors around their trim thrust at this
    airspeed (:func:`trim_rotor_thrusts`; none once the wing carries the weight, since in
    fixed-wing they are a reserve), plus the surfaces at full deflection."""
    T = trim_rotor_thrusts(af, airspeed_m_s)
    w = af.wing
    rotors = 0.0
    for r, t in zip(af.lift_rotors, T, strict=True):
        dT = min(float(t), r.max_thrust_N - float(t))
        rotors += {"roll": abs(float(r.position_m[1])), "pitch": abs(float(r.position_m[0])),
                   "yaw": r.torque_to_thrust_m}[axis] * dT
    qbar = 0.5 * af.air_density_kg_m3 * airspeed_m_s**2
    coef = {"roll": w.span_m * abs(w.Cl_da), "pitch": w.chord_m * abs(w.Cm_de),
            "yaw": w.span_m * abs(w.Cn_dr)}[axis]
    return float(rotors + qbar * w.area_m2 * coef * af.surfaces.max_deflection_rad)


def design_plant(af: Airframe, axis: Axis, airspeed_m_s: float, gamma: float = 0.0,
                 delays: LoopDelays = LoopDelays()) -> ct.StateSpace:
    """Moment -> [rate; angle] of eq. 1-3 behind the actuator lag with the loop's transport
    delay folded in: 1/((tau_act + T) s + 1), T = ``delays.transport_s`` (exp(-sT) ~
    1/(1 + sT) for w T << 1: T = 8 ms, crossovers below 20 rad/s; one state instead of a lag
    and a Pade pair, which keeps the tuning fast). The margins are checked against the exact
    delay (:func:`loop_margins`, :func:`stable_with_delay`)."""
    G = attitude_model(af, axis, airspeed_m_s, gamma)
    tau = actuator_time_constant(af) + max(0.0, delays.transport_s)
    return ct.series(ct.ss(ct.tf([1.0], [tau, 1.0])), G)


def delay_weight(tau_s: float) -> StateSpaceData:
    """W_delta(s) = k tau s / (tau s / 2 + 1) with the smallest k such that
    |W_delta(j w)| >= |exp(-j w t) - 1| for every t in [0, tau_s] and every w (the bound is
    2 |sin(w tau / 2)| for w tau <= pi and 2 beyond; k is found on a dense grid, 1 % added)."""
    x = np.logspace(-3, 3, 4000)
    bound = np.where(x < math.pi, 2.0 * np.abs(np.sin(x / 2.0)), 2.0)
    k = 1.01 * float(np.max(bound * np.sqrt(1.0 + (x / 2.0) ** 2) / x))
    # k tau s / (tau s/2 + 1) = 2k - 2k / (tau s/2 + 1)
    a = -2.0 / tau_s
    return (np.array([[a]]), np.array([[1.0]]), np.array([[-2.0 * k * (-a)]]),
            np.array([[2.0 * k]]))


def _overshoot_sensitivity_peak(overshoot: float) -> float:
    """Peak |S| of the unity loop whose closed loop is w^2 / (s^2 + 2 zeta w s + w^2) with
    the step overshoot ``overshoot`` (zeta = -ln OS / sqrt(pi^2 + ln^2 OS))."""
    lo = math.log(overshoot)
    z = -lo / math.sqrt(math.pi**2 + lo**2)
    x = np.logspace(-3, 3, 6000)
    s = 1j * x
    S = s * (s + 2 * z) / (s * s + 2 * z * s + 1.0)
    return float(np.max(np.abs(S)))


def sensitivity_rule(af: Airframe, axis: Axis, point: DesignPoint, u_max: float,
                     d_max: float, spec: RobustSpec = RobustSpec(),
                     ) -> tuple[SensitivityWeight, dict[str, float]]:
    """Ws of the documented rule (module docstring, d) and the numbers behind it."""
    J = axis_inertia(af, axis)
    w_act = actuator_bandwidth(af)
    w_u = authority_bandwidth(max(u_max - d_max, 1e-3 * u_max), J, R_MAX_RAD)
    wb = min(w_act / 8.0, w_u / 2.0)
    M = _overshoot_sensitivity_peak(spec.overshoot)
    return SensitivityWeight(M, wb, A_SENSITIVITY), {
        "omega_act_rad_s": w_act, "omega_u_rad_s": w_u, "omega_b_rad_s": wb, "M": M,
        "limited_by": "actuator bandwidth" if w_act / 8.0 <= w_u / 2.0 else "authority"}


def high_frequency_gain_bound(af: Airframe, u_max: float, spec: RobustSpec) -> dict[str, float]:
    """Bounds [N m s/rad] on kp_rate + kd_rate/tf from gyro noise (module docstring, g)."""
    s3 = 3.0 * spec.gyro_noise_rad_s
    noise = 0.05 * u_max / s3
    r_lim = min([r.rate_limit_per_s for r in af.lift_rotors]
                + [af.surfaces.rate_limit_rad_s / af.surfaces.max_deflection_rad])
    slew = u_max * r_lim * spec.delays.control_period_s / (2.0 * s3)
    return {"noise": noise, "slew": slew, "k_hf_max": min(noise, slew)}


def robust_parameters(af: Airframe, axis: Axis, u_max: float, spec: RobustSpec = RobustSpec(),
                      ) -> tuple[list[Parameter], dict[str, dict[str, Any]]]:
    """The five gains with physical bounds (module docstring, g), the classical start, and
    where each bound comes from.

    Every bound is a formula of the actuator bandwidth omega_act = 1 / tau_act
    (:func:`~vtolftc.synthesis.scaling.actuator_bandwidth`), the axis inertia J, the
    authority u_max about the axis (``u_max``, N m), the control period T and the
    high-frequency gain bound k_hf (:func:`high_frequency_gain_bound`, from gyro noise and
    the actuators' rate limits):

    - rate crossover limit omega_r,max = kp_hi / J with kp_hi = min(J omega_act, k_hf);
      start crossover omega_r = min(0.3 omega_act, 2 omega_u, omega_r,max) with omega_u =
      sqrt(u_max / (J r_max)) (the actuator lag costs at most atan(0.3) = 17 deg there);
    - kp_angle in [min(0.015 omega_act, omega_r / 4), omega_act / 2], start omega_r / 4
      (the outer loop no slower than 1/66 of the actuator bandwidth, a 3.3 s time constant
      for 50 ms actuators, unless the authority or gyro noise keep the rate loop so slow
      that a quarter of its crossover is slower: a cascade needs the outer loop about 4x
      below the inner one);
    - kp_rate in [J omega_act / 100, kp_hi], start min(J omega_r, kp_hi);
    - ki_rate in [J omega_act^2 / 4000, J omega_act^2 / 4], start kp0 omega_r / 5;
    - kd_rate in [0, min(2 J, k_hf tf_min)] (kd_rate / J is dimensionless), start 0.05 J;
    - tf_rate_s in [2.5 T, 20 tau_act], start 5 T.

    For DS-1 (omega_act = 20 rad/s, T = 4 ms): kp_angle >= 0.3, kp_rate >= 0.2 J, ki_rate
    >= 0.1 J, tf in [0.01, 1] s, the start's crossover capped at 6 rad/s.

    Raises
    ------
    AirframeError
        A gain with no admissible value (no authority about the axis).
    """
    J = axis_inertia(af, axis)
    w_act = actuator_bandwidth(af)
    tau = actuator_time_constant(af)
    T = spec.delays.control_period_s
    hf = high_frequency_gain_bound(af, u_max, spec)
    tf_min = 2.5 * T
    kp_hi = min(J * w_act, hf["k_hf_max"])
    kd_hi = min(2.0 * J, hf["k_hf_max"] * tf_min)
    ki_hi = J * w_act**2 / 4.0
    wr = min(0.3 * w_act, 2.0 * authority_bandwidth(u_max, J, R_MAX_RAD), kp_hi / J)
    kp0 = min(J * wr, kp_hi)
    b = {"kp_angle": (min(0.015 * w_act, wr / 4.0), w_act / 2.0),
         "kp_rate": (J * (w_act / 100), kp_hi),
         "ki_rate": (J * (w_act**2 / 4000), ki_hi),
         "kd_rate": (0.0, kd_hi),
         "tf_rate_s": (tf_min, 20 * tau)}
    require_bounds(af, axis, b)
    why = {
        "kp_angle": {"lower": b["kp_angle"][0], "upper": w_act / 2.0,
                     "lower_from": ("omega_act / 66" if b["kp_angle"][0] == 0.015 * w_act
                                    else "a quarter of the start's rate crossover"),
                     "upper_from": "outer loop <= omega_act / 2"},
        "kp_rate": {"lower": b["kp_rate"][0], "upper": kp_hi,
                    "upper_from": ("rate crossover <= omega_act" if kp_hi == J * w_act
                                   else "gyro noise (high-frequency gain)")},
        "ki_rate": {"lower": b["ki_rate"][0], "upper": ki_hi,
                    "upper_from": "integral zero below omega_act / 2"},
        "kd_rate": {"lower": 0.0, "upper": kd_hi,
                    "upper_from": ("2 J" if kd_hi == 2.0 * J
                                   else "gyro noise (kd / tf_min <= k_hf_max)")},
        "tf_rate_s": {"lower": tf_min, "upper": b["tf_rate_s"][1],
                      "lower_from": "2.5 control periods (below: near Nyquist)"},
        "k_hf": hf,
    }
    params = [
        Parameter("kp_angle", min(wr / 4.0, w_act / 2.0), *b["kp_angle"], scale=1.0),
        Parameter("kp_rate", max(kp0, b["kp_rate"][0]), *b["kp_rate"], scale=J),
        Parameter("ki_rate", min(max(kp0 * wr / 5.0, b["ki_rate"][0]), ki_hi),
                  *b["ki_rate"], scale=J),
        Parameter("kd_rate", min(0.05 * J, kd_hi), *b["kd_rate"], scale=0.1 * J),
        Parameter("tf_rate_s", max(5 * T, tf_min), *b["tf_rate_s"], scale=0.02),
    ]
    return params, why


@dataclass(frozen=True)
class RobustWeights(AxisWeights):
    """Weights of one axis at one point for the robust design: eq. 8's (about the centred
    nominal), the disturbance weight ``Wd`` (d_max / e_max, 0 if no rotor-out moment), the
    design plant's nominal (airspeed, gamma) and the numbers behind the rules."""

    nominal: tuple[float, float] = (0.0, 0.0)
    d_max_N_m: float = 0.0
    Wd: float = 0.0
    rule: dict[str, Any] | None = None
    delays: LoopDelays = LoopDelays()

    def to_dict(self) -> dict[str, Any]:
        """The weights, nominal point, rotor-out moment (N m), Wd and the Ws rule, as a dict."""
        return {**super().to_dict(), "nominal_airspeed_m_s": self.nominal[0],
                "nominal_gamma": self.nominal[1], "rotor_out_moment_N_m": self.d_max_N_m,
                "Wd": self.Wd, "Ws_rule": self.rule}

    def plant(self, af: Airframe) -> ct.StateSpace:
        """Design plant of this axis at the nominal (airspeed, gamma), loop delays included."""
        return design_plant(af, self.axis, self.nominal[0], self.nominal[1], self.delays)


def robust_weights(af: Airframe, axis: Axis, point: DesignPoint,
                   spec: RobustSpec = RobustSpec()) -> RobustWeights:
    """All weights of ``axis`` at ``point`` (module docstring a-d)."""
    nom = centred_nominal(af, axis, point)
    Wt, _ = cover(af, axis, point, nominal=nom)
    u_max = moment_authority_robust(af, axis, point.airspeed_m_s)
    require_authority(af, axis, point.airspeed_m_s, u_max)
    d = rotor_out_moment(af, axis, point.airspeed_m_s)
    Ws, rule = sensitivity_rule(af, axis, point, u_max, d, spec)
    M2, wb2 = TABLE2[axis][point.number - 1] if point.number <= 6 else (math.nan, math.nan)
    rule = {**rule, "table2_M": M2, "table2_omega_b_rad_s": wb2}
    Wd = d * EXCURSION_DESIGN_FACTOR / spec.excursion_rad
    return RobustWeights(axis, point, Ws, Wt, ControlWeight(R_MAX_RAD, u_max, OMEGA_A_RAD_S),
                         nominal=nom, d_max_N_m=d, Wd=Wd, rule=rule, delays=spec.delays)


def _scaled(W: Any, k: float) -> StateSpaceData:
    A, B, C, D = as_state_space(W.ss() if hasattr(W, "ss") else W.tf())
    return A, B, C * k, D * k


def _const(k: float) -> StateSpaceData:
    return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[k]])


def disturbance_weight(w: RobustWeights) -> StateSpaceData:
    """Wd(s) = Wd (s + w_i) / (s + 0.01 w_i): d_max / e_max above w_i, rising as 1/w below
    it (down to 0.01 w_i), so the angle error a constant moment leaves must also decay at
    least like an integrator of rate w_i = omega_b [rad/s] (the tracking bandwidth of Ws):
    after a rotor-out the loop recovers as fast as it tracks a reference. Without the rise
    the optimiser can drop the integral gain (the proportional plateau alone meets the peak).

    The recovery rate matters in flight, not only the peak: with w_i = min(0.5, omega_b / 2)
    (the design before) the hover pitch error of the worst rotor-out took 1.8 s to halve,
    and in a 4 m/s crosswind with a gust the vehicle drifted backwards into reversed flow
    and crashed (rotors 1b, 3b off in hover); with w_i = omega_b it halves in 0.8 s and
    both fly (``docs/ds1-claims/README.md``)."""
    wi = w.Ws.omega_b_rad_s
    # Wd (s + wi)/(s + e wi) = Wd + Wd wi (1 - e)/(s + e wi)
    e = 0.01
    return (np.array([[-e * wi]]), np.array([[1.0]]), np.array([[w.Wd * wi * (1 - e)]]),
            np.array([[w.Wd]]))


def _channels(af: Airframe, w: RobustWeights, G: Any, spec: RobustSpec,
              normalised: bool) -> list[tuple[str, CascadeChannel]]:
    floor = max(1.0, w.Wt.gain) if normalised else 1.0
    f = 1.0 / floor
    out = [("eq8", CascadeChannel(G, _scaled(w.Ws, f), _scaled(w.Wt, f), _scaled(w.Wr, f)))]
    if w.Wd > 0:
        out.append(("disturbance", CascadeChannel(G, Wd=disturbance_weight(w))))
    out.append(("delay", CascadeChannel(G, Wt=delay_weight(spec.delays.extra_margin_s))))
    return out


def _robust_problem(af: Airframe, axis: Axis, weights: list[RobustWeights], spec: RobustSpec,
                    ) -> tuple[TuningProblem, list[ct.StateSpace], list[CascadeChannel],
                               list[str], dict[str, dict[str, Any]]]:
    """The tuning problem of ``axis`` over the points of ``weights`` (all their channels)."""
    plants = [w.plant(af) for w in weights]
    chans, names = [], []
    for G, w in zip(plants, weights, strict=True):
        for nm, c in _channels(af, w, G, spec, True):
            chans.append(c)
            names.append(f"{axis} point {w.point.number} {nm}")
    u_max = min(w.Wr.u_max_N_m for w in weights)
    params, why = robust_parameters(af, axis, u_max, spec)
    return TuningProblem(params, chans, names), plants, chans, names, why


@dataclass(frozen=True)
class RobustMethod:
    """The robust design as a :class:`~vtolftc.synthesis.design_loop.DesignMethod`: weights
    of :func:`robust_weights`, the channels of the module docstring on the design plant,
    the tie-break on the eq. 8 channels, unnormalised norms reported."""

    spec: RobustSpec = RobustSpec()

    def weights(self, af: Airframe, axis: Axis, point: DesignPoint) -> RobustWeights:
        """:func:`robust_weights` ``(af, axis, point, spec)``."""
        return robust_weights(af, axis, point, self.spec)

    def setup(self, af: Airframe, axis: Axis, weights: list[RobustWeights]) -> TuningSetup:
        """The problem of every channel of every point of ``weights``."""
        pb, plants, chans, names, why = _robust_problem(af, axis, weights, self.spec)
        return TuningSetup(pb, plants, chans, (names, why))

    def design(self, axis: Axis, weights: list[RobustWeights], label: str, n_starts: int,
               setup: TuningSetup, res: TuneResult) -> AxisDesign:
        """The design of a finished tune: tie-break, unnormalised norms per point, poles."""
        spec = self.spec
        names, why = setup.extra
        eq8 = [c for c, n in zip(setup.chans, names, strict=True) if n.endswith("eq8")]
        theta = pick_start(res, eq8)
        per = []
        for G, w in zip(setup.plants, weights, strict=True):
            n = achieved_norms(CascadeChannel(G, w.Ws, w.Wt.tf(), w.Wr), theta)
            if w.Wd > 0:
                n["Wd*Sd"] = achieved_norms(CascadeChannel(G, Wd=disturbance_weight(w)),
                                            theta)["gamma"]
            wt = delay_weight(spec.delays.extra_margin_s)
            n["Wdelay*T"] = achieved_norms(CascadeChannel(G, Wt=wt), theta)["gamma"]
            n["tuned objective"] = float(res.value)
            per.append(n)
        norms = {k: max(p.get(k, 0.0) for p in per) for k in per[0] | per[-1]}
        poles = [closed_loop(G, theta).poles for G in setup.plants]
        stable = all(float(np.max(p.real)) < 0 for p in poles)
        gains = dict(zip(PARAM_NAMES, (float(x) for x in theta), strict=True))
        return AxisDesign(axis, label, gains, norms, stable,
                          [[complex(z) for z in p] for p in poles], list(weights),
                          n_starts + 1, res.message, per, bounds=why)


def robust_design_point(af: Airframe, axis: Axis, point: DesignPoint, *, n_starts: int = 4,
                        seed: int = 0, max_iter: int = 40,
                        spec: RobustSpec = RobustSpec()) -> AxisDesign:
    """Tune one axis at one point with the robust channels."""
    return tune_axis(RobustMethod(spec), af, axis, [robust_weights(af, axis, point, spec)],
                     f"point {point.number}", n_starts, point_seed(seed, axis, point.number),
                     max_iter)


def robust_design_shif(af: Airframe, axis: Axis,
                       points: Sequence[DesignPoint] | None = None, *,
                       n_starts: int = 4, seed: int = 0, max_iter: int = 40,
                       spec: RobustSpec = RobustSpec()) -> AxisDesign:
    """One constant P-PID over all points (default :func:`robust_points`) with the robust
    channels of every point."""
    pts = robust_points(af) if points is None else points
    ws = [robust_weights(af, axis, p, spec) for p in pts]
    return tune_axis(RobustMethod(spec), af, axis, ws, "all points", n_starts,
                     point_seed(seed, axis, SHIF_TAG), max_iter)


def run_robust_designs(af: Airframe, *, n_starts: int = 4, seed: int = 0,
                       points: Sequence[DesignPoint] | None = None,
                       executor: Executor | None = None, shif: bool = True,
                       progress: Callable[[str], None] | None = None,
                       spec: RobustSpec = RobustSpec(), max_iter: int = 40,
                       on_design: Callable[[tuple[str, int], AxisDesign], None] | None = None,
                       ) -> tuple[dict[Axis, list[AxisDesign]], dict[Axis, AxisDesign]]:
    """All robust GS-SHIF tunes (axes x ``points``, default :func:`robust_points`) and the
    SHIF tunes over the same points: :func:`vtolftc.synthesis.design_loop.run_design_loop`
    with :class:`RobustMethod` (deterministic, the same bit for bit with or without
    ``executor``, as one :func:`robust_design_shif` / :func:`robust_design_point` call per
    tune; ``progress`` and ``on_design`` as there).
    """
    pts = robust_points(af) if points is None else tuple(points)
    return run_design_loop(RobustMethod(spec), af, pts, n_starts=n_starts, seed=seed,
                           executor=executor, shif=shif, progress=progress,
                           max_iter=max_iter, on_design=on_design)


# ------------------------------------------------------------------------------------------
# checks of a designed loop
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LoopMargins:
    """Margins of the loop broken at the plant input, L_u = K_rate (kp_angle G_angle +
    G_rate), on the design plant (lag and modelled delay included).

    ``delay_margin_s``: the smallest extra loop delay that destabilises (min over gain
    crossovers of phase margin / crossover frequency; inf if |L_u| never crosses 1);
    ``disk_alpha``: balanced (skew 0) disk margin alpha = 2 / max_w |S_u - T_u| with
    S_u = 1/(1 + L_u), T_u = L_u/(1 + L_u) (python-control ``disk_margins``, tested);
    ``disk_gain_margin`` = (1 + alpha/2)/(1 - alpha/2) and ``disk_phase_margin_deg`` =
    2 atan(alpha/2): the gain and phase variations it guarantees simultaneously;
    ``phase_margin_deg`` (smallest over the crossovers), ``crossover_rad_s`` (the crossover
    that sets the delay margin).
    """

    delay_margin_s: float
    crossover_rad_s: float
    phase_margin_deg: float
    disk_alpha: float
    disk_gain_margin: float
    disk_phase_margin_deg: float

    def to_dict(self) -> dict[str, float]:
        """All margins as a dict of floats."""
        return dict(self.__dict__)


def loop_frequency_response(G: Any, theta: Any, omegas: NDArray[np.float64],
                            ) -> NDArray[np.complex128]:
    """L_u(j w) of plant ``G`` (moment -> [rate; angle]) and gains ``theta``."""
    th = [theta[k] for k in PARAM_NAMES] if isinstance(theta, dict) else list(theta)
    F = frequency_response(G, omegas)
    K = frequency_response(rate_controller(th[1], th[2], th[3], th[4]), omegas)[:, 0, 0]
    return K * (th[0] * F[:, 1, 0] + F[:, 0, 0])


def loop_margins(G: Any, theta: Any, omegas: NDArray[np.float64] | None = None,
                 ) -> LoopMargins:
    """Delay and disk margins of the loop (see :class:`LoopMargins`)."""
    w = np.logspace(-3, 4, 6000) if omegas is None else np.asarray(omegas, float)
    L = loop_frequency_response(G, theta, w)
    m = np.abs(L)
    idx = np.nonzero(np.diff(np.sign(m - 1.0)) != 0)[0]
    dm, wc_best, pm_best = math.inf, math.nan, math.inf
    for i in idx:
        # interpolate the crossing in log frequency
        a, b = math.log(m[i]), math.log(m[i + 1])
        t = a / (a - b) if a != b else 0.0
        wc = math.exp(math.log(w[i]) + t * (math.log(w[i + 1]) - math.log(w[i])))
        Lc = loop_frequency_response(G, theta, np.array([wc]))[0]
        pm = (math.pi + math.atan2(Lc.imag, Lc.real)) % (2 * math.pi)
        if pm / wc < dm:
            dm, wc_best = pm / wc, wc
        pm_best = min(pm_best, pm)
    S = 1.0 / (1.0 + L)
    T = L / (1.0 + L)
    alpha = float(2.0 / np.max(np.abs(S - T))) if np.all(np.isfinite(S)) else 0.0
    if alpha < 2.0:
        gm = (1 + alpha / 2) / (1 - alpha / 2)
        pmd = math.degrees(2 * math.atan(alpha / 2))
    else:
        gm, pmd = math.inf, 90.0
    return LoopMargins(dm, wc_best, math.degrees(pm_best) if math.isfinite(pm_best)
                       else math.inf, alpha, gm, pmd)


def stable_with_delay(G: Any, theta: Any, delay_s: float, order: int = 8) -> bool:
    """Closed-loop stability with ``delay_s`` more delay at the plant input (Pade of order
    ``order``), an independent check of the delay margin."""
    P = ct.series(ct.ss(ct.tf(*ct.pade(delay_s, order))), ct.ss(G)) if delay_s > 0 else G
    return closed_loop(ct.ss(P), theta).stable()


def disturbance_peak(G: Any, theta: Any, d_N_m: float, t_end_s: float = 10.0) -> float:
    """Peak |angle| [rad] of the linear closed loop after a moment step ``d_N_m`` at the
    plant input (what one rotor-out does to the nominal loop)."""
    if d_N_m == 0:
        return 0.0
    cl = closed_loop(G, theta)
    sys = ct.ss(cl.A, cl.B[:, [1]], cl.C[[3], :], np.zeros((1, 1)))
    t = np.linspace(0.0, t_end_s, 4001)
    r = ct.step_response(sys, t)
    return float(np.max(np.abs(np.asarray(r.outputs).reshape(-1)))) * abs(d_N_m)
