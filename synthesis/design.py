"""The paper's attitude design: weights, structured H-infinity tuning at the six design points
for the three axes (GS-SHIF), and the constant multi-model design over all points (SHIF).

Weights per axis and design point (paper section 3.1.3):

- ``Ws`` (eq. 5) with the paper's table 2 values of M and omega_b (:data:`TABLE2`) and
  A = 1e-3 (0.1 % steady-state error; A > 0 is required for a finite weighted norm; the
  integral action of the P-PID makes S(0) = 0, so A hardly matters).
- ``Wt``: the multiplicative uncertainty weight fitted by
  :func:`vtolftc.synthesis.uncertainty.cover`
  over the point's airspeed range and gamma in [0, 0.6].
- ``Wr`` (eq. 6) with omega_a = 5 rad/s (paper), r_max = 30 deg (the largest attitude
  reference step the autopilot commands) and u_max = :func:`moment_authority` (the moment the
  airframe can produce about the axis at the nominal airspeed).

Tunable gains (:data:`vtolftc.synthesis.loops.PARAM_NAMES`) with bounds (:func:`parameters`):
kp_angle in [0.3, 8] 1/s (outer loop of a few rad/s at most; PX4's default roll P is 6.5);
kp_rate in [0.5 J, 40 J] N m s/rad (the rate-loop crossover kp_rate/J between 0.5 and
40 rad/s); ki_rate in [2 J, 40 J] N m/rad; kd_rate in [0, 2 J] N m s^2/rad; tf_rate_s in
[0.01, 1] s (the autopilot runs at 250 Hz: a derivative filter faster than 0.01 s would act
near its Nyquist frequency). J is the axis inertia (kg m^2).

The lower bound of ki_rate is a design decision, not the paper's: eq. 8 only weighs the
reference-to-error S, not the rejection of a constant moment at the plant input (what an
actuator fault produces), and the integral gain raises |T_u| and |S| around crossover, so the
optimiser drives ki_rate to its lower bound for roll (whose plant already integrates). With
ki_rate >= 2 J the integral removes a fault's constant moment in a few seconds; in the paper's
case 1 the roll RMSE drops from 1.84 to 1.28 deg against ki_rate >= 0.5 J, for a stacked
norm a few percent higher (roll point 6: 0.679 -> 0.700).

Start point: a classical design (rate-loop crossover omega_r = min(6, sqrt(4 u_max /
(r_max J))) rad/s, kp_rate = J omega_r, ki_rate = kp_rate omega_r / 5, kd_rate = 0.05 J,
tf = 0.02 s, kp_angle = omega_r / 4), plus ``n_starts`` seeded random starts.

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

import math
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, as_completed
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.hinfnorm import hinf_norm
from vtolftc.synthesis.loops import (
    PARAM_NAMES,
    CascadeChannel,
    ControlWeight,
    SensitivityWeight,
    closed_loop,
)
from vtolftc.synthesis.models import AXES, Axis, attitude_model
from vtolftc.synthesis.structured import (
    Parameter,
    StartRecord,
    TuneResult,
    TuningProblem,
    collect_starts,
    run_start,
    start_jobs,
    tune,
)
from vtolftc.synthesis.uncertainty import PAPER_DESIGN_POINTS, DesignPoint, UncertaintyWeight, cover

__all__ = [
    "A_SENSITIVITY",
    "OMEGA_A_RAD_S",
    "R_MAX_RAD",
    "TABLE2",
    "AxisDesign",
    "AxisWeights",
    "design_gs_shif",
    "design_point",
    "design_shif",
    "moment_authority",
    "parameters",
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
    """Ws (table 2), Wt (``cover``) and Wr (eq. 6) of ``axis`` at ``point``."""
    tab = TABLE2 if table2 is None else table2
    M, wb = tab[axis][point.number - 1]
    Wt, _ = cover(af, axis, point)
    u_max = moment_authority(af, axis, point.airspeed_m_s)
    return AxisWeights(axis, point, SensitivityWeight(M, wb, A_SENSITIVITY), Wt,
                       ControlWeight(R_MAX_RAD, u_max, OMEGA_A_RAD_S))


def axis_inertia(af: Airframe, axis: Axis) -> float:
    """The principal moment of inertia of ``axis`` (kg m^2, FRD body axes)."""
    return float(np.diag(af.inertia_kg_m2)[AXES.index(axis)])


def parameters(af: Airframe, axis: Axis, u_max: float) -> list[Parameter]:
    """The five tunable gains with bounds and the classical start (module docstring)."""
    J = axis_inertia(af, axis)
    wr = min(6.0, math.sqrt(4.0 * u_max / (R_MAX_RAD * J)))
    kp = J * wr
    return [
        Parameter("kp_angle", wr / 4.0, 0.3, 8.0, scale=1.0),
        Parameter("kp_rate", kp, 0.5 * J, 40.0 * J, scale=J),
        Parameter("ki_rate", max(kp * wr / 5.0, 2.0 * J), 2.0 * J, 40.0 * J, scale=J),
        Parameter("kd_rate", 0.05 * J, 0.0, 2.0 * J, scale=0.1 * J),
        Parameter("tf_rate_s", 0.02, 0.01, 1.0, scale=0.02),
    ]


@dataclass
class AxisDesign:
    """Result of one tune: gains, per-requirement norms, closed-loop poles, weights used.

    ``norms`` keys: ``gamma`` (the stacked norm of eq. 8, max over models for SHIF),
    ``Ws*S``, ``Wt*T``, ``Wr*R`` (each requirement alone; for SHIF the max over models).
    """

    axis: Axis
    label: str                      # "point 3" or "all points"
    gains: dict[str, float]
    norms: dict[str, float]
    stable: bool
    poles: list[list[complex]]      # closed-loop poles per model
    weights: list[AxisWeights]
    starts: int
    message: str = ""
    per_model_norms: list[dict[str, float]] = field(default_factory=list)

    @property
    def theta(self) -> NDArray[np.float64]:
        """The P-PID gains as a vector in :data:`PARAM_NAMES` order."""
        return np.array([self.gains[k] for k in PARAM_NAMES])


def achieved_norms(ch: CascadeChannel, theta: NDArray[np.float64]) -> dict[str, float]:
    """The exact H-infinity norm of the channel (``"gamma"``) and of each of its weighted rows
    (e.g. ``"Ws*S"``) at the gains ``theta``, by name."""
    out = {"gamma": hinf_norm(ch(theta)).value}
    for name, sys in ch.rows(theta).items():
        out[name] = hinf_norm(sys).value
    return out


def _secondary(ch: CascadeChannel, theta: NDArray[np.float64]) -> float:
    """||Ws S||_inf: the tie-break among equally good starts (module docstring)."""
    A, B, C, D = ch(theta)
    keep = [i for i, n in enumerate(ch.outputs) if n == "Ws*S"]
    return hinf_norm((A, B, C[keep], D[keep])).value if keep else 0.0


def pick_start(res: TuneResult, channels: Sequence[CascadeChannel]) -> NDArray[np.float64]:
    """Tie-break among near-optimal starts (module docstring)."""
    if not res.stable:
        return res.theta
    best = res.value
    cands = [r for r in res.starts if math.isfinite(r.value) and r.value <= best * (1 + 1e-3)]
    scored = [(max(_secondary(c, r.theta) for c in channels), r.index, r.theta) for r in cands]
    scored.sort(key=lambda t: (t[0], t[1]))
    return np.asarray(scored[0][2], float)


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


def _design(axis: Axis, weights: list[AxisWeights], label: str, n_starts: int,
            plants: list[Any], chans: list[CascadeChannel], res: TuneResult) -> AxisDesign:
    """The design of a finished tune: tie-break, norms per point, poles."""
    theta = pick_start(res, chans)
    per = [achieved_norms(c, theta) for c in chans]
    norms = {k: max(p[k] for p in per) for k in per[0]}
    poles = [closed_loop(G, theta).poles for G in plants]
    stable = all(float(np.max(p.real)) < 0 for p in poles)
    return AxisDesign(axis, label, dict(zip(PARAM_NAMES, (float(x) for x in theta),
                                            strict=True)),
                      norms, stable, [[complex(z) for z in p] for p in poles], weights,
                      n_starts + 1, res.message, per)


def _tune(af: Airframe, axis: Axis, weights: list[AxisWeights], label: str, n_starts: int,
          seed: int, max_iter: int) -> AxisDesign:
    pb, plants, chans = _problem(af, axis, weights)
    res = tune(pb, n_starts=n_starts, seed=seed, max_iter=max_iter)
    return _design(axis, weights, label, n_starts, plants, chans, res)


def point_seed(seed: int, axis: Axis, tag: int) -> int:
    """The random-start seed of one tune: independent streams per (seed, axis, point tag)."""
    return int(np.random.SeedSequence([seed, AXES.index(axis), tag]).generate_state(1)[0])


def design_point(af: Airframe, axis: Axis, point: DesignPoint, *, n_starts: int = 6,
                 seed: int = 0, max_iter: int = 40) -> AxisDesign:
    """Tune one axis at one design point (eq. 7-8 for the nominal model of the point)."""
    w = weights_for(af, axis, point)
    return _tune(af, axis, [w], f"point {point.number}", n_starts,
                 point_seed(seed, axis, point.number), max_iter)


def design_shif(af: Airframe, axis: Axis, points: Sequence[DesignPoint] = PAPER_DESIGN_POINTS,
                *, n_starts: int = 6, seed: int = 0, max_iter: int = 40) -> AxisDesign:
    """One constant P-PID for ``axis`` minimising the max over all points of the stacked
    norm (multi-model minimax, the same weights per point as GS-SHIF)."""
    ws = [weights_for(af, axis, p) for p in points]
    return _tune(af, axis, ws, "all points", n_starts, point_seed(seed, axis, 100), max_iter)


def _job(args: tuple[Any, ...]) -> tuple[tuple[str, int], AxisDesign]:
    kind, af, axis, point, n_starts, seed = args
    if kind == "gs":
        return (axis, point.number), design_point(af, axis, point, n_starts=n_starts, seed=seed)
    return (axis, 0), design_shif(af, axis, n_starts=n_starts, seed=seed)


def _weights_job(args: tuple[Any, ...]) -> tuple[tuple[str, DesignPoint], AxisWeights]:
    af, axis, point = args
    return (axis, point), weights_for(af, axis, point)


def _gs_job(args: tuple[Any, ...]) -> tuple[tuple[str, int], AxisDesign]:
    """One GS-SHIF tune with its point's weights given (:func:`design_point`)."""
    af, axis, w, n_starts, seed, max_iter = args
    return (axis, w.point.number), _tune(af, axis, [w], f"point {w.point.number}", n_starts,
                                         point_seed(seed, axis, w.point.number), max_iter)


def _start_job(args: tuple[Any, ...]) -> tuple[tuple[str, int], StartRecord]:
    axis, job = args
    return (axis, int(job[1])), run_start(job)


def run_designs(af: Airframe, *, n_starts: int = 6, seed: int = 0,
                points: Sequence[DesignPoint] = PAPER_DESIGN_POINTS,
                executor: Executor | None = None, shif: bool = True,
                progress: Callable[[str], None] | None = None, max_iter: int = 40,
                on_design: Callable[[tuple[str, int], AxisDesign], None] | None = None,
                ) -> tuple[dict[Axis, list[AxisDesign]], dict[Axis, AxisDesign]]:
    """All GS-SHIF tunes (axes x points) and, with ``shif``, the three SHIF tunes (over the
    paper's six points, :func:`design_shif`'s default).

    Deterministic: each tune's seed derives from (seed, axis, point), whatever the execution
    order. ``executor`` (e.g. a ``ProcessPoolExecutor``) runs the work in parallel, cut finer
    than one job per tune so that every worker stays busy: the weights of every (axis,
    point) once, then every start of the SHIF tunes (the longest jobs, first) and the
    GS-SHIF tunes; a SHIF tune's start records are combined in start order
    (:func:`vtolftc.synthesis.structured.collect_starts`), the same result bit for bit as
    :func:`design_shif`. ``progress`` is called with a label after each finished tune,
    ``on_design(key, design)`` with each finished design (key ``(axis, point number)``,
    ``(axis, 0)`` for SHIF).
    """
    results: dict[tuple[str, int], AxisDesign] = {}

    def done(key: tuple[str, int], d: AxisDesign) -> None:
        results[key] = d
        if on_design is not None:
            on_design(key, d)
        if progress is not None:
            progress(f"{key[0]} {'SHIF' if key[1] == 0 else f'point {key[1]}'}")

    if executor is None:
        jobs: list[tuple[Any, ...]] = []
        if shif:  # the longest jobs first
            jobs += [("shif", af, ax, None, n_starts, seed) for ax in AXES]
        jobs += [("gs", af, ax, p, n_starts, seed) for ax in AXES for p in points]
        for key, d in map(_job, jobs):
            done(key, d)
    else:
        need = list(points) + [p for p in PAPER_DESIGN_POINTS if shif and p not in points]
        wfuts = [executor.submit(_weights_job, (af, ax, p)) for ax in AXES for p in need]
        weights = dict(f.result() for f in wfuts)
        shif_pb: dict[Axis, tuple[Any, ...]] = {}
        records: dict[Axis, list[StartRecord]] = {ax: [] for ax in AXES}
        futs = []
        if shif:
            for ax in AXES:
                ws = [weights[(ax, p)] for p in PAPER_DESIGN_POINTS]
                prob = _problem(af, ax, ws)
                shif_pb[ax] = (ws, prob)
                for job in start_jobs(prob[0], n_starts=n_starts, seed=point_seed(seed, ax, 100),
                                      max_iter=max_iter):
                    futs.append(executor.submit(_start_job, (ax, job)))
        futs += [executor.submit(_gs_job, (af, ax, weights[(ax, p)], n_starts, seed,
                                           max_iter)) for ax in AXES for p in points]
        for f in as_completed(futs):
            key, r = f.result()
            if isinstance(r, AxisDesign):
                done(key, r)
                continue
            ax = key[0]
            records[ax].append(r)
            if len(records[ax]) == n_starts + 1:
                ws, (pb, plants, chans) = shif_pb[ax]
                res = collect_starts(pb, records[ax])
                done((ax, 0), _design(ax, ws, "all points", n_starts, plants, chans, res))
    gs = {ax: [results[(ax, p.number)] for p in points] for ax in AXES}
    sh = {ax: results[(ax, 0)] for ax in AXES} if shif else {}
    return gs, sh


def design_gs_shif(af: Airframe, **kw: Any) -> dict[Axis, list[AxisDesign]]:
    """GS-SHIF only (see :func:`run_designs`)."""
    return run_designs(af, shif=False, **kw)[0]
