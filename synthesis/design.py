"""The paper's attitude design: weights, structured H-infinity tuning at the six design points
for the three axes (GS-SHIF), and the constant multi-model design over all points (SHIF).

Design points: the paper's table 1 scaled to the airframe's transition range
(:func:`paper_points`: table 1's airspeeds times V_t / 13 m/s, V_t the transition end derived
from the wing or declared, :mod:`vtolftc.synthesis.scaling`); table 1 itself for DS-1.

Weights per axis and design point (paper section 3.1.3):

- ``Ws`` (eq. 5) with the paper's table 2 values of M and omega_b (:data:`TABLE2`) and
  A = 1e-3 (0.1 % steady-state error; A > 0 is required for a finite weighted norm; the
  integral action of the P-PID makes S(0) = 0, so A hardly matters). Table 2 holds for DS-1;
  for another aircraft M is kept and omega_b scaled by the ratio of the authority bandwidths
  sqrt(u_max / (J r_max)) of the two aircraft at the same point (:func:`table2_scaled`).
- ``Wt``: the multiplicative uncertainty weight fitted by
  :func:`vtolftc.synthesis.uncertainty.cover`
  over the point's airspeed range and gamma in [0, 0.6].
- ``Wr`` (eq. 6) with omega_a = 5 rad/s (paper; scaled by the actuator bandwidth for another
  aircraft, :func:`control_weight_bandwidth`), r_max = 30 deg (the largest attitude
  reference step the autopilot commands) and u_max = :func:`moment_authority` (the moment the
  airframe can produce about the axis at the nominal airspeed).

Tunable gains (:data:`vtolftc.synthesis.loops.PARAM_NAMES`) with bounds (:func:`parameters`,
which gives each as a formula of the actuator bandwidth omega_act = 1 / tau_act, the
autopilot period T = 4 ms and the axis inertia J; the numbers here are DS-1's, omega_act =
20 rad/s): kp_angle in [0.3, 8] 1/s (outer loop of a few rad/s at most; PX4's default roll
P is 6.5); kp_rate in [0.5 J, 40 J] N m s/rad (the rate-loop crossover kp_rate/J between
0.5 and 40 rad/s); ki_rate in [2 J, 40 J] N m/rad; kd_rate in [0, 2 J] N m s^2/rad;
tf_rate_s in [0.01, 1] s (the autopilot runs at 250 Hz: a derivative filter faster than
0.01 s would act near its Nyquist frequency). J is the axis inertia (kg m^2).

The lower bound of ki_rate is a design decision, not the paper's: eq. 8 only weighs the
reference-to-error S, not the rejection of a constant moment at the plant input (what an
actuator fault produces), and the integral gain raises |T_u| and |S| around crossover, so the
optimiser drives ki_rate to its lower bound for roll (whose plant already integrates). With
ki_rate >= 2 J the integral removes a fault's constant moment in a few seconds; in the paper's
case 1 the roll RMSE drops from 1.84 to 1.28 deg against ki_rate >= 0.5 J, for a stacked
norm a few percent higher (roll point 6: 0.679 -> 0.700).

Start point: a classical design (rate-loop crossover omega_r = min(0.3 omega_act,
sqrt(4 u_max / (r_max J))) rad/s (a 6 rad/s cap for DS-1), kp_rate = J omega_r, ki_rate =
kp_rate omega_r / 5, kd_rate = 0.05 J, tf = 0.02 s, kp_angle = omega_r / 4), plus
``n_starts`` seeded random starts.

Tie-break: among the starts whose stacked norm is within 0.1 % of the best, the one with the
smallest ||Ws S||_inf is kept. Where a low-frequency floor of |Wt T_u| (= |Wt(0)|, since
T_u(0) = 1 with integral action) dominates the stacked norm (pitch 1-3 and yaw 1-4 for DS-1;
for SHIF the worst point's floor), eq. 8 does not determine the gains: every start reaching
the floor is optimal, ||Wr R|| is already bounded by gamma, and the nominal tracking
requirement decides (as a ``systune`` user would make Wt T a hard and Ws S a soft goal).
Picking the smallest ||Wr R|| instead gives the least aggressive loops of the set, which fly
markedly worse (yaw RMSE about 3 deg instead of 0.3 deg in the paper's case 1).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtolftc.airframe.loader import Airframe, load_airframe
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
from vtolftc.synthesis.loops import (
    PARAM_NAMES,
    CascadeChannel,
    ControlWeight,
    SensitivityWeight,
    closed_loop,
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
from vtolftc.synthesis.uncertainty import PAPER_DESIGN_POINTS, DesignPoint, UncertaintyWeight, cover

__all__ = [
    "A_SENSITIVITY",
    "OMEGA_A_RAD_S",
    "R_MAX_RAD",
    "TABLE2",
    "AxisDesign",
    "AxisWeights",
    "PaperMethod",
    "achieved_norms",
    "axis_inertia",
    "control_weight_bandwidth",
    "design_gs_shif",
    "design_point",
    "design_shif",
    "moment_authority",
    "paper_points",
    "parameters",
    "pick_start",
    "point_seed",
    "reference_airframe",
    "run_designs",
    "table2_scaled",
    "weights_for",
]

A_SENSITIVITY = 1e-3
OMEGA_A_RAD_S = 5.0
R_MAX_RAD = math.radians(30.0)

# Paper table 2: (M, omega_b [rad/s]) per design point 1..6.
TABLE2: dict[str, tuple[tuple[float, float], ...]] = {
    "roll": ((2.0, 2.4), (1.1, 0.5), (1.6, 1.1), (2.0, 1.2), (1.9, 1.1), (1.8, 0.6)),
    "pitch": ((1.1, 0.012), (2.0, 0.2), (15.3, 0.059), (1.3, 0.16), (1.3, 0.89), (1.4, 0.82)),
    "yaw": ((1.8, 0.1), (1.3, 0.002), (1.8, 0.003), (1.1, 0.007), (1.5, 0.006), (2.5, 2.9)),
}


def moment_authority(af: Airframe, axis: Axis, airspeed_m_s: float) -> float:
    """u_max [N m]: the moment the airframe can produce about ``axis`` at ``airspeed_m_s``.

    Lift rotors: each at its hover share T_h = m g / n_rotors of thrust can change by
    dT = min(T_h, T_max - T_h) (up on one side, down on the other); roll moment sum |y_i| dT,
    pitch sum |x_i| dT, yaw sum k_Q dT (reaction torque, k_Q = torque-to-thrust ratio). The
    rotors keep their hover share through the transition (the paper's lift rotors stay
    active up to 13 m/s; while the wing unloads them the headroom only changes sides).
    Surfaces at full deflection delta_max: roll qbar S b Cl_da, pitch qbar S c |Cm_de|,
    yaw qbar S b |Cn_dr|. Pushers are not counted (they only push forward).
    """
    w = af.wing
    n = len(af.lift_rotors)
    th = af.weight_N / n
    rotors = 0.0
    for r in af.lift_rotors:
        dT = min(th, r.max_thrust_N - th)
        if axis == "roll":
            rotors += abs(float(r.position_m[1])) * dT
        elif axis == "pitch":
            rotors += abs(float(r.position_m[0])) * dT
        else:
            rotors += r.torque_to_thrust_m * dT
    qbar = 0.5 * af.air_density_kg_m3 * airspeed_m_s**2
    dmax = af.surfaces.max_deflection_rad
    coef = {"roll": w.span_m * abs(w.Cl_da), "pitch": w.chord_m * abs(w.Cm_de),
            "yaw": w.span_m * abs(w.Cn_dr)}[axis]
    return float(rotors + qbar * w.area_m2 * coef * dmax)


@dataclass(frozen=True)
class AxisWeights:
    """Weights of one axis at one design point."""

    axis: Axis
    point: DesignPoint
    Ws: SensitivityWeight
    Wt: UncertaintyWeight
    Wr: ControlWeight

    def to_dict(self) -> dict[str, Any]:
        """Ws, Wt and Wr parameters as a JSON-ready dict."""
        return {"Ws": self.Ws.to_dict(), "Wt": self.Wt.to_dict(), "Wr": self.Wr.to_dict()}


def weights_for(af: Airframe, axis: Axis, point: DesignPoint,
                table2: dict[str, Sequence[tuple[float, float]]] | None = None,
                ) -> AxisWeights:
    """Ws (table 2 scaled to ``af``, :func:`table2_scaled`; or ``table2`` as given), Wt
    (``cover``) and Wr (eq. 6, omega_a of :func:`control_weight_bandwidth`) of ``axis`` at
    ``point``.

    Raises
    ------
    AirframeError
        ``af`` has no moment about ``axis`` at the point's airspeed.
    """
    u_max = moment_authority(af, axis, point.airspeed_m_s)
    require_authority(af, axis, point.airspeed_m_s, u_max)
    M, wb = (table2_scaled(af, axis, point) if table2 is None
             else table2[axis][point.number - 1])
    Wt, _ = cover(af, axis, point)
    return AxisWeights(axis, point, SensitivityWeight(M, wb, A_SENSITIVITY), Wt,
                       ControlWeight(R_MAX_RAD, u_max, control_weight_bandwidth(af)))


def table2_scaled(af: Airframe, axis: Axis, point: DesignPoint) -> tuple[float, float]:
    """(M, omega_b [rad/s]) of Ws for ``axis`` at ``point``: table 2 scaled to ``af``.

    Table 2 was designed for the paper's aircraft, of which the reference airframe DS-1
    (``airframe/ds1.toml``) is our stand-in; for DS-1 this is table 2 itself. For another
    aircraft the peak M (dimensionless: a robustness margin) is kept and the bandwidth is
    scaled with the aircraft's attitude time scale at the same fraction of its transition:

        omega_b = omega_b,table2 * omega_u(af, V) / omega_u(DS-1, V_table1)

    with omega_u = sqrt(u_max / (J r_max)) (:func:`~vtolftc.synthesis.scaling.
    authority_bandwidth`, u_max = :func:`moment_authority`, J the axis inertia) at the
    point's airspeed V (the table 1 airspeed of the same point number for DS-1): an aircraft
    with twice the inertia for the same authority tracks sqrt(2) times slower.
    """
    M, wb = TABLE2[axis][point.number - 1]
    ref = reference_airframe()
    v_ref = PAPER_DESIGN_POINTS[point.number - 1].airspeed_m_s
    u = moment_authority(af, axis, point.airspeed_m_s)
    require_authority(af, axis, point.airspeed_m_s, u)
    wu = authority_bandwidth(u, axis_inertia(af, axis), R_MAX_RAD)
    wu_ref = authority_bandwidth(moment_authority(ref, axis, v_ref), axis_inertia(ref, axis),
                                 R_MAX_RAD)
    return M, wb * (wu / wu_ref)


def control_weight_bandwidth(af: Airframe) -> float:
    """omega_a [rad/s] of Wr (eq. 6): the paper's 5 rad/s for DS-1, scaled with the actuator
    bandwidth, omega_a = 5 omega_act(af) / omega_act(DS-1)
    (:func:`~vtolftc.synthesis.scaling.actuator_bandwidth`)."""
    return OMEGA_A_RAD_S * (actuator_bandwidth(af) / actuator_bandwidth(reference_airframe()))


@functools.lru_cache(maxsize=1)
def reference_airframe() -> Airframe:
    """DS-1 (``airframe/ds1.toml``), the stand-in for the paper's aircraft that table 2's
    weights were designed for (loaded once)."""
    return load_airframe(None)


def parameters(af: Airframe, axis: Axis, u_max: float) -> list[Parameter]:
    """The five tunable gains with bounds and the classical start (module docstring), scaled
    by the actuator bandwidth omega_act = 1 / tau_act, the autopilot period T and the
    authority bandwidth omega_u (:mod:`vtolftc.synthesis.scaling`):

    - kp_angle in [min(0.015 omega_act, omega_r / 4), 0.4 omega_act] 1/s;
    - kp_rate in [J omega_act / 40, 2 J omega_act] (rate crossover kp_rate / J);
    - ki_rate in [J omega_act^2 / 200, J omega_act^2 / 10];
    - kd_rate in [0, 2 J] (kd_rate / J is dimensionless);
    - tf_rate_s in [2.5 T, 20 tau_act];
    - start: omega_r = min(0.3 omega_act, 2 omega_u) (actuator lag at most atan(0.3) =
      17 deg at the start's crossover), kp_rate = J omega_r, ki_rate = max(kp_rate
      omega_r / 5, lower bound), kd_rate = 0.05 J, tf = 5 T, kp_angle = omega_r / 4.

    For DS-1 (omega_act = 20 rad/s, T = 4 ms) these are the bounds of the module docstring.
    """
    J = axis_inertia(af, axis)
    w_act = actuator_bandwidth(af)
    tau = actuator_time_constant(af)
    T = AUTOPILOT_PERIOD_S
    wr = min(0.3 * w_act, 2.0 * authority_bandwidth(u_max, J, R_MAX_RAD))
    kp = J * wr
    b = {"kp_angle": (min(0.015 * w_act, wr / 4.0), 0.4 * w_act),
         "kp_rate": (J * (w_act / 40), J * (2 * w_act)),
         "ki_rate": (J * (w_act**2 / 200), J * (w_act**2 / 10)),
         "kd_rate": (0.0, 2.0 * J), "tf_rate_s": (2.5 * T, 20 * tau)}
    require_bounds(af, axis, b)

    def clip(name: str, x: float) -> float:
        return min(max(x, b[name][0]), b[name][1])

    return [
        Parameter("kp_angle", clip("kp_angle", wr / 4.0), *b["kp_angle"], scale=1.0),
        Parameter("kp_rate", clip("kp_rate", kp), *b["kp_rate"], scale=J),
        Parameter("ki_rate", clip("ki_rate", max(kp * wr / 5.0, b["ki_rate"][0])),
                  *b["ki_rate"], scale=J),
        Parameter("kd_rate", 0.05 * J, *b["kd_rate"], scale=0.1 * J),
        Parameter("tf_rate_s", 5 * T, *b["tf_rate_s"], scale=0.02),
    ]


def _problem(af: Airframe, axis: Axis, weights: list[AxisWeights],
             ) -> tuple[TuningProblem, list[Any], list[CascadeChannel]]:
    """The multi-model problem of ``axis`` over the points of ``weights`` (eq. 7-8)."""
    plants = [attitude_model(af, axis, w.point.airspeed_m_s) for w in weights]
    chans = [CascadeChannel(G, w.Ws, w.Wt.tf(), w.Wr) for G, w in zip(plants, weights,
                                                                      strict=True)]
    u_max = min(w.Wr.u_max_N_m for w in weights)
    pb = TuningProblem(parameters(af, axis, u_max), chans,
                       [f"{axis} point {w.point.number}" for w in weights])
    return pb, plants, chans


@dataclass(frozen=True)
class PaperMethod:
    """The paper's design as a :class:`~vtolftc.synthesis.design_loop.DesignMethod`: weights
    of :func:`weights_for`, eq. 8 on the eq. 1-3 model, tie-break of :func:`pick_start`."""

    def weights(self, af: Airframe, axis: Axis, point: DesignPoint) -> AxisWeights:
        """:func:`weights_for` ``(af, axis, point)``."""
        return weights_for(af, axis, point)

    def setup(self, af: Airframe, axis: Axis, weights: list[AxisWeights]) -> TuningSetup:
        """The eq. 7-8 problem over the points of ``weights``."""
        pb, plants, chans = _problem(af, axis, weights)
        return TuningSetup(pb, plants, chans)

    def design(self, axis: Axis, weights: list[AxisWeights], label: str, n_starts: int,
               setup: TuningSetup, res: TuneResult) -> AxisDesign:
        """The design of a finished tune: tie-break, norms per point, poles."""
        theta = pick_start(res, setup.chans)
        per = [achieved_norms(c, theta) for c in setup.chans]
        norms = {k: max(p[k] for p in per) for k in per[0]}
        poles = [closed_loop(G, theta).poles for G in setup.plants]
        stable = all(float(np.max(p.real)) < 0 for p in poles)
        return AxisDesign(axis, label, dict(zip(PARAM_NAMES, (float(x) for x in theta),
                                                strict=True)),
                          norms, stable, [[complex(z) for z in p] for p in poles], weights,
                          n_starts + 1, res.message, per)


def paper_points(af: Airframe) -> tuple[DesignPoint, ...]:
    """The paper method's six design points for ``af``: table 1 scaled to its transition
    range (:func:`~vtolftc.synthesis.scaling.scaled_design_points`; table 1 for DS-1)."""
    return scaled_design_points(af, cruise=False)


def design_point(af: Airframe, axis: Axis, point: DesignPoint, *, n_starts: int = 6,
                 seed: int = 0, max_iter: int = 40) -> AxisDesign:
    """Tune one axis at one design point (eq. 7-8 for the nominal model of the point)."""
    return tune_axis(PaperMethod(), af, axis, [weights_for(af, axis, point)],
                     f"point {point.number}", n_starts, point_seed(seed, axis, point.number),
                     max_iter)


def design_shif(af: Airframe, axis: Axis, points: Sequence[DesignPoint] | None = None,
                *, n_starts: int = 6, seed: int = 0, max_iter: int = 40) -> AxisDesign:
    """One constant P-PID for ``axis`` minimising the max over all points (default
    :func:`paper_points`) of the stacked norm (multi-model minimax, the same weights per
    point as GS-SHIF)."""
    pts = paper_points(af) if points is None else points
    ws = [weights_for(af, axis, p) for p in pts]
    return tune_axis(PaperMethod(), af, axis, ws, "all points", n_starts,
                     point_seed(seed, axis, SHIF_TAG), max_iter)


def run_designs(af: Airframe, *, n_starts: int = 6, seed: int = 0,
                points: Sequence[DesignPoint] | None = None,
                executor: Executor | None = None, shif: bool = True,
                progress: Callable[[str], None] | None = None, max_iter: int = 40,
                on_design: Callable[[tuple[str, int], AxisDesign], None] | None = None,
                ) -> tuple[dict[Axis, list[AxisDesign]], dict[Axis, AxisDesign]]:
    """All GS-SHIF tunes (axes x ``points``, default :func:`paper_points`) and, with
    ``shif``, the three SHIF tunes over the six paper points of ``af`` (:func:`design_shif`'s
    default): :func:`vtolftc.synthesis.design_loop.run_design_loop` with
    :class:`PaperMethod` (deterministic, the same bit for bit with or without
    ``executor``; ``progress`` and ``on_design`` as there).
    """
    pts = paper_points(af) if points is None else tuple(points)
    return run_design_loop(PaperMethod(), af, pts, shif_points=paper_points(af),
                           n_starts=n_starts, seed=seed, executor=executor, shif=shif,
                           progress=progress, max_iter=max_iter, on_design=on_design)


def design_gs_shif(af: Airframe, **kw: Any) -> dict[Axis, list[AxisDesign]]:
    """GS-SHIF only (see :func:`run_designs`)."""
    return run_designs(af, shif=False, **kw)[0]
