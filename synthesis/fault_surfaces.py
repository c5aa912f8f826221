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
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
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
from vtolftc.synthesis.models import Axis
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
    """

    sp: SurfaceProblem
    af: Airframe
    axis: Axis
    caps: NDArray[np.float64]
    cases: Sequence[FaultCase]
    rho: float = PENALTY_DEG

    def __post_init__(self) -> None:
        self._inputs: list[list[tuple[float, float, Any, float]]] = []

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
        return math.degrees(math.sqrt(sum(x * x for x in vals) / len(vals)))

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


def design_fault_surfaces(method: DesignMethod, af: Airframe, axis: Axis,
                          grid: Sequence[DesignPoint], degree: int = 1, *,
                          cases: Sequence[FaultCase] | None = None, slack: float = 0.05,
                          n_starts: int = 1, hinf_max_iter: int | None = 5,
                          max_evals: int = 300, seed: int = 0,
                          hinf: SurfaceDesign | None = None,
                          reference: Mapping[str, float] | None = None,
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
    f0 = FaultObjective(sp0, af, axis, caps, cs)
    th0, _, n0 = _minimise(f0, th_ref, max_evals)
    const = sp0.surface(th0)
    t2 = time.perf_counter()
    spd = surface_problem(method, af, axis, grid, degree, start=const, weights=ws)
    fd = FaultObjective(spd, af, axis, caps, cs)
    start = spd.problem.initial
    thd, Jd, nd = _minimise(fd, start, max_evals)
    Js = fd(start)
    kept = not (Jd <= Js)
    if kept:
        thd, Jd = start, Js
    t3 = time.perf_counter()
    return FaultSurfaceDesign(
        hinf, const, spd.surface(thd), Js, Jd, f0.predicted_deg(th0), fd.predicted_deg(thd),
        sp0.problem.objective(th0), spd.problem.objective(thd), h_ref, slack, kept,
        {"constant": n0, "surface": nd},
        {"hinf": t1 - t0, "constant": t2 - t1, "surface": t3 - t2})
