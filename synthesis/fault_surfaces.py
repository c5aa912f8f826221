"""Gain surfaces designed for the predicted fault response (table 4), H-infinity kept as a
constraint.

The H-infinity surface design (:func:`vtolftc.synthesis.surfaces.design_surfaces`) minimises
the max over the grid of the robust channels' norms; a lower value of that does not give a
lower nonlinear RMSE after the paper's faults (``benchmarks/bench_surfaces.py``). This design
minimises, over the same surface coefficients,

    J(theta) = RMSE_pred(theta) + rho * sum_i max(0, ||ch_i(theta)||_inf / cap_i - 1)

- ``RMSE_pred`` [deg]: the root mean square over the paper's cases 1 and 2 of the predicted
  RMSE of the axis (:func:`vtolftc.synthesis.fault_objective.predicted_rmse`: the closed loop
  of the design plant with the surface's gains at each airspeed the case passes through,
  step of the fault's trim moment at the plant input, effectiveness loss in the plant);
- the H-infinity terms as constraints: every channel of the robust surface problem (eq. 8
  normalised by its floor, the rotor-out disturbance channel, the delay channel) at every
  grid airspeed stays below ``cap_i`` = ``(1 + slack)`` times the reference design's worst
  norm of that requirement over the grid (the reference: a given constant P-PID, e.g. the
  shipped robust SHIF, or else the H-infinity-optimal constant surface). Meaning: no
  requirement (tracking and robust stability of eq. 8, rotor-out excursion, the 50 ms
  extra delay margin) gets more than ``slack`` (5 %) worse anywhere on the grid than the
  reference's worst; the new designs trade nothing the reference did not already trade;
- ``rho`` [deg per unit relative violation]: 10 deg, so that exceeding a cap by 1 % costs
  0.1 deg, more than any RMSE the predictor can gain (the predicted RMSEs are 0.05-1 deg):
  the caps act as hard constraints, and J is the predicted RMSE wherever they hold.

SHIF is the degree-0 surface minimising J, started from the reference; GS-SHIF the
degree-d surface started from that SHIF embedded (the same gains at every airspeed); both
minimise the same J with the same optimiser (bounded Nelder-Mead in coordinates scaled by
the gains' typical values), and the surface keeps its start if the optimiser returns
anything worse, so J(GS-SHIF) <= J(SHIF) by construction.

Options of :func:`design_fault_surfaces` (all off by default: the design of
``gains/surface/`` is reproduced unchanged):

- ``margins``: the validation's loop margins (6 dB, 30 deg, 50 ms; targets 4 % above) at
  every grid airspeed as constraints with the same ``rho``
  (:mod:`~vtolftc.synthesis.margin_constraints`);
- ``nominal``: the nominal rest of the transition (t >= 24 s of table 4) added to the
  prediction in quadrature (:mod:`~vtolftc.synthesis.nominal_objective`);
- ``max_degree``: GS-SHIF's degree chosen by J (each degree started from the one below,
  kept only if it lowers J by more than ``degree_gain``, 1 %);
- ``lazy``: the simplex of :mod:`~vtolftc.synthesis.lazy_simplex` on
  :meth:`FaultObjective.bounded`, restarted from its best while budget remains.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.design_loop import DesignMethod
from vtolftc.synthesis.fault_objective import (
    PAPER_CASES,
    FaultCase,
    fault_inputs,
    ppid_controller,
    rmse_from_inputs,
)
from vtolftc.synthesis.hinfnorm import as_state_space, hinf_norm
from vtolftc.synthesis.lazy_simplex import lazy_nelder_mead
from vtolftc.synthesis.loops import PARAM_NAMES
from vtolftc.synthesis.margin_constraints import MarginConstraints
from vtolftc.synthesis.models import Axis
from vtolftc.synthesis.nominal_objective import (
    NominalStep,
    nominal_inputs,
    nominal_rmse_from_inputs,
)
from vtolftc.synthesis.surfaces import (
    GainSurface,
    SurfaceBasis,
    SurfaceDesign,
    SurfaceProblem,
    design_surfaces,
    surface_problem,
)
from vtolftc.synthesis.uncertainty import DesignPoint

__all__ = ["FaultObjective", "FaultSurfaceDesign", "design_fault_surfaces"]

#: Penalty weight rho [deg per unit relative violation of a cap].
PENALTY_DEG = 10.0


@dataclass
class FaultObjective:
    """J(theta) of the module docstring on one surface problem.

    Parameters
    ----------
    sp : SurfaceProblem
        The robust surface problem (its channels give the H-infinity terms).
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    caps : ndarray of float, shape (n_channels,)
        Upper bounds of the channels' norms.
    cases : sequence of FaultCase
        The fault cases whose predicted RMSEs are combined (root mean square).
    rho : float
        Penalty weight [deg].
    margins : MarginConstraints, optional
        Loop-margin requirements at the grid airspeeds
        (:mod:`~vtolftc.synthesis.margin_constraints`), penalised with the same ``rho``.
    nominal_steps : sequence of NominalStep, optional
        Reference steps of the nominal rest of the transition
        (:mod:`~vtolftc.synthesis.nominal_objective`); their predicted RMSE adds to the
        fault's in quadrature. None: the fault transient only.
    """

    sp: SurfaceProblem
    af: Airframe
    axis: Axis
    caps: NDArray[np.float64]
    cases: Sequence[FaultCase]
    rho: float = PENALTY_DEG
    margins: MarginConstraints | None = None
    nominal_steps: Sequence[NominalStep] | None = None

    def __post_init__(self) -> None:
        self._inputs: list[list[tuple[float, float, Any, float]]] = []
        self._nominal: list[tuple[NominalStep, Any]] | None = None
        self._order: NDArray[np.intp] | None = None
        self.stops = {"prediction": 0, "margins": 0, "caps": 0, "full": 0}

    def predicted_deg(self, theta: NDArray[np.float64]) -> float:
        """Root mean square over the cases of the predicted RMSE [deg].

        Parameters
        ----------
        theta : ndarray of float
            Surface coefficients, gain-major.

        Returns
        -------
        float
            [deg] (inf if a loop on the way is unstable).
        """
        if not self._inputs:
            self._inputs = [fault_inputs(self.af, self.axis, c) for c in self.cases]
        sf = self.sp.surface(theta)
        vals = [rmse_from_inputs(inp, lambda v: ppid_controller(sf.gains_at(v)), c)
                for inp, c in zip(self._inputs, self.cases, strict=True)]
        ms = sum(x * x for x in vals) / len(vals)
        if self.nominal_steps is not None:
            if self._nominal is None:
                self._nominal = nominal_inputs(self.af, self.axis, self.nominal_steps)
            n = nominal_rmse_from_inputs(self._nominal,
                                         lambda v: ppid_controller(sf.gains_at(v)))
            ms += n * n
        return math.degrees(math.sqrt(ms))

    def margin_violation(self, theta: NDArray[np.float64]) -> float:
        """The margin penalty v (dimensionless; 0 without margin constraints).

        Parameters
        ----------
        theta : ndarray of float
            Surface coefficients, gain-major.

        Returns
        -------
        float
            v of :mod:`~vtolftc.synthesis.margin_constraints`.
        """
        if self.margins is None:
            return 0.0
        sf = self.sp.surface(theta)
        return self.margins.violation(sf.gain_matrix(list(self.margins.airspeeds_m_s)))

    def bounded(self, theta: NDArray[np.float64], bound: float) -> float:
        """J, computed only as far as needed to know whether it is below ``bound``.

        The terms are added cheapest first (prediction, margins, then the caps one channel
        at a time, the most binding first); as soon as the partial sum reaches ``bound`` it
        is returned (a lower bound of J, >= ``bound``). Below ``bound`` the value is J
        exactly (:mod:`~vtolftc.synthesis.lazy_simplex`).

        Parameters
        ----------
        theta : ndarray of float
            Surface coefficients, gain-major.
        bound : float
            The threshold [deg] (inf: always exact).

        Returns
        -------
        float
            [deg].
        """
        theta = np.asarray(theta, float)
        acc = self.predicted_deg(theta)
        if not math.isfinite(acc):
            return math.inf
        if acc >= bound:
            self.stops["prediction"] += 1
            return acc
        acc += self.rho * self.margin_violation(theta)
        if acc >= bound:
            self.stops["margins"] += 1
            return acc
        pb = self.sp.problem
        chans = pb.channels
        if self._order is None:
            n0 = pb.channel_norms(theta)
            self._order = np.argsort(-(n0 / self.caps), kind="stable")
        for i in self._order:
            A, B, C, D = as_state_space(chans[i](theta))
            if pb.stability_margin > 0 and A.size and (
                    np.max(np.linalg.eigvals(A).real) >= -pb.stability_margin):
                return math.inf
            n = hinf_norm((A, B, C, D)).value
            if not math.isfinite(n):
                return math.inf
            acc += self.rho * max(0.0, n / float(self.caps[i]) - 1.0)
            if acc >= bound:
                self.stops["caps"] += 1
                return acc
        self.stops["full"] += 1
        return acc

    def violation(self, theta: NDArray[np.float64]) -> float:
        """Sum over channels of the relative violation of their caps (0 when all hold).

        Parameters
        ----------
        theta : ndarray of float
            Surface coefficients, gain-major.

        Returns
        -------
        float
            Dimensionless (inf if a channel is unstable).
        """
        n = self.sp.problem.channel_norms(np.asarray(theta, float))
        return float(np.sum(np.maximum(0.0, n / self.caps - 1.0)))

    def __call__(self, theta: NDArray[np.float64]) -> float:
        p = self.predicted_deg(theta)
        if not math.isfinite(p):
            return math.inf
        v = self.violation(theta)
        if self.margins is not None:
            v += self.margin_violation(theta)
        return p + self.rho * v if math.isfinite(v) else math.inf


def channel_kind(name: str) -> str:
    """The requirement a surface channel stands for, from its name.

    Parameters
    ----------
    name : str
        A surface problem's channel name, e.g. ``"roll point 3 delay @ 7 m/s"``.

    Returns
    -------
    str
        ``"eq8"``, ``"disturbance"`` or ``"delay"``.

    Examples
    --------
    >>> channel_kind("roll point 3 delay @ 7 m/s")
    'delay'
    """
    head = name.split(" @ ")[0]
    return head.rsplit(" ", 1)[-1]


def _caps(sp: SurfaceProblem, ref_norms: NDArray[np.float64], slack: float,
          ) -> NDArray[np.float64]:
    names = list(sp.problem.channel_names or [])
    kinds = [channel_kind(n) for n in names]
    worst = {k: max(float(v) for v, kk in zip(ref_norms, kinds, strict=True) if kk == k)
             for k in set(kinds)}
    return np.array([(1.0 + slack) * worst[k] for k in kinds])


def _minimise(f: FaultObjective, theta0: NDArray[np.float64], max_evals: int,
              ) -> tuple[NDArray[np.float64], float, int]:
    pb = f.sp.problem
    lo, hi, sc = pb.lower, pb.upper, pb.scales
    z_lo, z_hi = (lo - theta0) / sc, (hi - theta0) / sc

    def g(z: NDArray[np.float64]) -> float:
        return f(np.clip(theta0 + z * sc, lo, hi))

    f0 = g(np.zeros_like(theta0))
    res = minimize(g, np.zeros_like(theta0), method="Nelder-Mead",
                   bounds=list(zip(z_lo, z_hi, strict=True)),
                   options={"maxfev": max_evals, "xatol": 1e-4, "fatol": 1e-5,
                            "initial_simplex": _simplex(theta0.size)})
    if not (float(res.fun) <= f0):
        return theta0, f0, int(res.nfev)
    return np.clip(theta0 + res.x * sc, lo, hi), float(res.fun), int(res.nfev)


def _simplex(n: int, step: float = 0.2) -> NDArray[np.float64]:
    s = np.zeros((n + 1, n))
    s[1:] = step * np.eye(n)
    return s


def _minimise_lazy(f: FaultObjective, theta0: NDArray[np.float64], max_evals: int,
                   ) -> tuple[NDArray[np.float64], float, int]:
    """:func:`_minimise`'s problem (same scaled coordinates, simplex and tolerances) by
    :func:`~vtolftc.synthesis.lazy_simplex.lazy_nelder_mead` on :meth:`FaultObjective.bounded`;
    returns the start when nothing better was found."""
    pb = f.sp.problem
    lo, hi, sc = pb.lower, pb.upper, pb.scales

    def g(z: NDArray[np.float64], bound: float) -> float:
        return f.bounded(np.clip(theta0 + z * sc, lo, hi), bound)

    n = theta0.size
    z_lo, z_hi = (lo - theta0) / sc, (hi - theta0) / sc
    z, fz, nfev = lazy_nelder_mead(g, _simplex(n), z_lo, z_hi, max_evals)
    while nfev < max_evals - 2 * (n + 1):
        # restart from the best with a fresh simplex (the penalty's kinks stall a simplex)
        z2, f2, k = lazy_nelder_mead(g, z + _simplex(n), z_lo, z_hi, max_evals - nfev)
        nfev += k
        if not (f2 < fz):
            break
        z, fz = z2, f2
    f0 = f.bounded(theta0, math.inf)
    if not (fz < f0):
        return theta0, f0, nfev
    return np.clip(theta0 + z * sc, lo, hi), fz, nfev


@dataclass
class FaultSurfaceDesign:
    """SHIF and GS-SHIF of one axis designed on J (module docstring).

    Parameters
    ----------
    hinf : SurfaceDesign or None
        The H-infinity surface design the caps come from (its constant is the start), None
        when a reference was given.
    constant, surface : GainSurface
        SHIF (degree 0) and GS-SHIF (degree d) on J.
    constant_J, surface_J : float
        J of each [deg] (``surface_J <= constant_J``).
    constant_pred_deg, surface_pred_deg : float
        Their predicted RMSE [deg].
    constant_hinf, surface_hinf : float
        Their H-infinity objective (max channel norm on the grid).
    h_ref, slack : float
        The reference's H-infinity objective (max channel norm) and the allowed relative
        increase of each requirement.
    kept_start : bool
        True when the surface optimiser returned a worse point and SHIF was kept.
    evaluations : dict of str to int
        Objective evaluations of each stage.
    time_s : dict of str to float
        Wall time of each stage [s].
    degree_J : dict of int to float
        J [deg] of GS-SHIF at each degree tried.
    """

    hinf: SurfaceDesign | None
    constant: GainSurface
    surface: GainSurface
    constant_J: float
    surface_J: float
    constant_pred_deg: float
    surface_pred_deg: float
    constant_hinf: float
    surface_hinf: float
    h_ref: float
    slack: float
    kept_start: bool
    evaluations: dict[str, int]
    time_s: dict[str, float]
    degree_J: dict[int, float] = field(default_factory=dict)


def design_fault_surfaces(method: DesignMethod, af: Airframe, axis: Axis,
                          grid: Sequence[DesignPoint], degree: int = 1, *,
                          cases: Sequence[FaultCase] | None = None, slack: float = 0.05,
                          n_starts: int = 1, hinf_max_iter: int | None = 5,
                          max_evals: int = 300, seed: int = 0,
                          hinf: SurfaceDesign | None = None,
                          reference: Mapping[str, float] | None = None,
                          margins: bool = False, nominal: bool = False, lazy: bool = False,
                          max_degree: int | None = None, degree_gain: float = 0.01,
                          constant_starts: Sequence[Mapping[str, float]] = (),
                          ) -> FaultSurfaceDesign:
    """H-infinity SHIF (the caps and the start), then SHIF and GS-SHIF on J.

    Parameters
    ----------
    method : DesignMethod
        The point design whose channels make the H-infinity terms (e.g. ``RobustMethod()``).
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    grid : sequence of DesignPoint
        The airspeed grid (:func:`~vtolftc.synthesis.surfaces.surface_grid`).
    degree : int
        Degree of GS-SHIF's surface (>= 1).
    cases : sequence of FaultCase, optional
        Default the paper's cases 1 and 2.
    slack : float
        Allowed relative increase of each requirement's worst norm over the reference's.
    n_starts, hinf_max_iter : int
        Random starts and iteration cap of the H-infinity SHIF tune.
    max_evals : int
        Evaluations of J per stage (SHIF, GS-SHIF).
    seed : int
        Seed of the H-infinity tune.
    hinf : SurfaceDesign, optional
        An H-infinity design already made on ``grid`` (skips that tune).
    reference : mapping of str to float, optional
        The gains of a constant P-PID to take the caps and the start from instead of the
        H-infinity SHIF (e.g. the shipped robust SHIF's; no H-infinity tune then).
    margins : bool
        Add the loop-margin requirements (6 dB, 30 deg, 50 ms, targets 4 % above) at every
        grid airspeed as constraints (:class:`~vtolftc.synthesis.margin_constraints.
        MarginConstraints`, penalty ``rho``).
    nominal : bool
        Add the nominal-transition term (:data:`~vtolftc.synthesis.nominal_objective.
        NOMINAL_STEPS` of the axis) to the prediction.
    lazy : bool
        Minimise with :func:`~vtolftc.synthesis.lazy_simplex.lazy_nelder_mead` (cap norms
        skipped where the cheaper terms already decide) instead of scipy's Nelder-Mead.
    max_degree : int, optional
        Choose GS-SHIF's degree by the objective instead of ``degree``: degree 1 started
        from SHIF, then each degree d + 1 started from degree d's surface, kept only while
        it lowers J by more than ``degree_gain`` (relative) below degree d's; the first
        degree that does not stops the search. The chosen degree is
        ``surface.basis.degree``; ``degree_J`` records J per degree tried.
    degree_gain : float
        The relative decrease of J a higher degree must bring.
    constant_starts : sequence of mapping of str to float, optional
        Further starts of the SHIF stage (P-PID gains, :data:`~vtolftc.synthesis.loops.
        PARAM_NAMES`), each minimised with the same budget after the reference's; SHIF is
        the lowest J of all (a local simplex started where the constraints fail can stall
        there: a start inside them lets SHIF meet what GS-SHIF meets).

    Returns
    -------
    FaultSurfaceDesign
        Both designs.
    """
    cs = list(cases) if cases is not None else [PAPER_CASES["1"], PAPER_CASES["2"]]
    t0 = time.perf_counter()
    ws = [method.weights(af, axis, p) for p in grid]
    if reference is None:
        if hinf is None:
            hinf = design_surfaces(method, af, axis, grid, 0, n_starts=n_starts, seed=seed,
                                   max_iter=hinf_max_iter)
        ref = hinf.constant
    else:
        ref = GainSurface.constant(SurfaceBasis(0, grid[0].airspeed_m_s,
                                                grid[-1].airspeed_m_s), reference)
    t1 = time.perf_counter()
    sp0 = surface_problem(method, af, axis, grid, 0, start=ref, weights=ws)
    th_ref = sp0.problem.initial
    ref_norms = sp0.problem.channel_norms(th_ref)
    h_ref = float(np.max(ref_norms))
    caps = _caps(sp0, ref_norms, slack)
    mc = (MarginConstraints(af, axis, [p.airspeed_m_s for p in grid]) if margins else None)
    steps = None
    if nominal:
        from vtolftc.synthesis.nominal_objective import NOMINAL_STEPS

        steps = NOMINAL_STEPS[axis]
    minimise = _minimise_lazy if lazy else _minimise

    def objective(sp: SurfaceProblem) -> FaultObjective:
        return FaultObjective(sp, af, axis, caps, cs, margins=mc, nominal_steps=steps)

    f0 = objective(sp0)
    th0, J0, n0 = minimise(f0, th_ref, max_evals)
    for g in constant_starts:
        th_s = np.clip(np.array([float(g[k]) for k in PARAM_NAMES]), sp0.problem.lower,
                       sp0.problem.upper)
        th_k, J_k, n_k = minimise(f0, th_s, max_evals)
        n0 += n_k
        if J_k < J0:
            th0, J0 = th_k, J_k
    const = sp0.surface(th0)
    t2 = time.perf_counter()
    evals = {"constant": n0}
    degrees = [degree] if max_degree is None else list(range(1, max_degree + 1))
    start_surface = const
    best: tuple[SurfaceProblem, FaultObjective, NDArray[np.float64], float] | None = None
    degree_J: dict[int, float] = {}
    Js = math.nan
    rejected = False
    for d in degrees:
        spd = surface_problem(method, af, axis, grid, d, start=start_surface, weights=ws)
        fd = objective(spd)
        start = spd.problem.initial
        J_start = fd.bounded(start, math.inf) if lazy else fd(start)
        if best is None:
            Js = J_start                      # SHIF on the degree-d problem
        thd, Jd, nd = minimise(fd, start, max_evals)
        if not (Jd <= J_start):
            thd, Jd = start, J_start
            rejected = rejected or best is None
        evals[f"surface degree {d}"] = nd
        degree_J[d] = Jd
        if best is not None and not (Jd < best[3] * (1.0 - degree_gain)):
            break
        best = (spd, fd, thd, Jd)
        start_surface = spd.surface(thd)
    assert best is not None
    spd, fd, thd, Jd = best
    kept = rejected if max_degree is None else not (Jd < Js)
    if max_degree is None:
        evals = {"constant": n0, "surface": evals[f"surface degree {degree}"]}
    t3 = time.perf_counter()
    out = FaultSurfaceDesign(
        hinf, const, spd.surface(thd), Js, Jd, f0.predicted_deg(th0), fd.predicted_deg(thd),
        sp0.problem.objective(th0), spd.problem.objective(thd), h_ref, slack, kept,
        evals, {"hinf": t1 - t0, "constant": t2 - t1, "surface": t3 - t2}, degree_J)
    return out
