"""D-K iteration on gain surfaces: robust performance designed for over the whole envelope.

The D-K iteration of :mod:`vtolftc.synthesis.dk` (exact D step, D(s) fit, K step on
||D N D^-1||) with the gains of an axis a surface K(V) (:mod:`vtolftc.synthesis.surfaces`)
instead of one point's gains. At every airspeed V_i of the surface grid:

- **N_i** is paper eq. 14 on the robust design plant at V_i's centred nominal
  (:func:`~vtolftc.synthesis.dk.cascade_rp`, the weights of
  :func:`~vtolftc.synthesis.robust.robust_weights` at the grid point: W_t the multiplicative
  input cover of the point's airspeed range x loss of effectiveness gamma in [0, 0.6], Ws the
  robust rule's tracking weight, Wr eq. 6), evaluated at the surface's gains K(V_i);
- **D step**: the exact d_i(w) of the two-block structure and a stable, minimum-phase
  D_i(s) of order <= 2 fitted to it (:meth:`~vtolftc.synthesis.dk.MuProfile.scaling`);
- **floor** f_i = max(1, |W_t,i(0)|): with the integral action every P-PID here has,
  T_u(0) = 1, so mu_RS,i >= |W_t,i(0)| and mu_RP,i >= f_i for any gains (the robust design
  normalises its eq. 8 channel by the same number).

Then **one** multi-model K step over the surface coefficients (SHIF: degree 0, one constant
P-PID; GS-SHIF: degree d >= 1) minimises

    J = max( max_i ||D_i N_i(K(V_i)) D_i^-1||_inf / (f_i B),  max_ij ||R_ij|| / r_ij )

with B the first term's value at the K step's start (so J = 1 there) and R_ij the
requirement channels kept at every grid point (the 50 ms delay-margin channel and the
rotor-out channel of :mod:`~vtolftc.synthesis.robust`), each divided by r_ij = max(1, its
norm at the start of the iteration): a requirement met there stays met, an unmet one does
not get worse. The K step keeps its start if the tuner returns a worse J, so it **never
increases the worst floor-normalised scaled norm** max_i ||D_i N_i D_i^-1|| / f_i (with the
D_i it was given). The measured objective of an iteration is M = max_i mu_hat_i / f_i (the
exact D step on the frequency grid): "every grid point meets robust performance, or sits at
the floor no integral controller beats" is M <= 1. The best iteration by M is returned,
iteration 0 (the start) included.

GS-SHIF starts from the SHIF result embedded in the degree-d basis (the same gains at every
airspeed, bit for bit), so its M is never above SHIF's (:func:`dk_surfaces`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.dk import (
    MuProfile,
    Normalised,
    RationalScaling,
    ScaledChannel,
    cascade_rp,
    mu_profile,
)
from vtolftc.synthesis.hinfnorm import hinf_norm
from vtolftc.synthesis.loops import PARAM_NAMES, CascadeChannel
from vtolftc.synthesis.models import Axis
from vtolftc.synthesis.robust import (
    RobustSpec,
    delay_weight,
    disturbance_weight,
    robust_parameters,
    robust_weights,
)
from vtolftc.synthesis.structured import Parameter, TuningProblem, tune
from vtolftc.synthesis.surfaces import (
    GainSurface,
    SurfaceBasis,
    SurfaceChannel,
    coefficient_parameters,
)
from vtolftc.synthesis.uncertainty import DesignPoint

#: The robust design's default settings (DS-1's declared requirements).
_SPEC = RobustSpec()

__all__ = ["GridModel", "SurfaceDKProblem", "SurfaceDKResult", "SurfaceDKSettings",
           "SurfaceDKStep", "dk_surface", "dk_surfaces", "surface_dk_problem"]


@dataclass(frozen=True)
class SurfaceDKSettings:
    """Settings of a surface D-K iteration.

    Parameters
    ----------
    max_iter : int, optional
        Maximum D-K iterations (K steps), >= 1.
    order : {0, 1, 2}, optional
        Order of every D_i(s).
    rel_tol : float, optional
        Stop when the measured M falls by less than this fraction of the best so far.
    tune_iter : int, optional
        Iteration cap of each K step's tune.
    n_omegas : int, optional
        Frequencies of the D step, log-spaced over 1e-3..1e3 rad/s.
    keep_requirements : bool, optional
        Keep the delay-margin and rotor-out channels in the K step.
    scaled : bool, optional
        Scale by D_i (False: the K step minimises the unscaled ||N_i|| / f_i, a diagnostic
        of what the D scaling buys).
    """

    max_iter: int = 3
    order: int = 2
    rel_tol: float = 0.01
    tune_iter: int = 20
    n_omegas: int = 121
    keep_requirements: bool = True
    scaled: bool = True

    def omegas(self) -> NDArray[np.float64]:
        """The D step's frequency grid.

        Returns
        -------
        ndarray of float, shape (n_omegas,)
            Log-spaced over 1e-3..1e3 rad/s.
        """
        return np.logspace(-3, 3, self.n_omegas)

    def to_dict(self) -> dict[str, Any]:
        """The settings as a JSON-ready dict.

        Returns
        -------
        dict of str to object
            The fields by name.
        """
        return dict(self.__dict__)


@dataclass
class GridModel:
    """One grid airspeed of the problem.

    Parameters
    ----------
    point : DesignPoint
        The grid point (airspeed and perturbed range, m/s).
    rp : callable
        gains -> N (:class:`~vtolftc.synthesis.dk.CascadeRP`).
    requirements : list
        Requirement channels gains -> (A, B, C, D) (delay margin, rotor-out).
    floor : float
        f = max(1, |W_t(0)|), the integral-action floor of mu_RP (module docstring).
    weights : RobustWeights
        The point's weights (for independent analysis).
    """

    point: DesignPoint
    rp: Any
    requirements: list[Any]
    floor: float
    weights: Any


@dataclass
class SurfaceDKProblem:
    """The grid models of one axis and the gain parameters (bounds, scales).

    Parameters
    ----------
    axis : {"roll", "pitch", "yaw"}
        The axis.
    models : list of GridModel
        By increasing airspeed.
    gain_parameters : list of Parameter
        The robust design's five gain parameters over the grid (bounds from the smallest
        authority on it).
    """

    axis: Axis
    models: list[GridModel]
    gain_parameters: list[Parameter]

    @property
    def airspeeds_m_s(self) -> list[float]:
        """The grid airspeeds [m/s]."""
        return [m.point.airspeed_m_s for m in self.models]

    @property
    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(lower, upper) gain bounds, shape (5,) each."""
        return (np.array([p.lower for p in self.gain_parameters]),
                np.array([p.upper for p in self.gain_parameters]))

    def constant(self, gains: Mapping[str, float], degree: int = 0) -> GainSurface:
        """The constant surface of ``gains`` over the grid, in the problem's bounds.

        Parameters
        ----------
        gains : mapping of str to float
            The P-PID gains (:data:`PARAM_NAMES`).
        degree : int, optional
            Basis degree.

        Returns
        -------
        GainSurface
            The surface (c_0 clipped into the bounds).
        """
        lo, hi = self.bounds
        vs = self.airspeeds_m_s
        g = {k: float(np.clip(gains[k], lo[i], hi[i])) for i, k in enumerate(PARAM_NAMES)}
        return GainSurface.constant(SurfaceBasis(degree, min(vs), max(vs)), g, lower=lo,
                                    upper=hi)

    def profiles(self, surface: GainSurface, omegas: NDArray[np.float64]) -> list[MuProfile]:
        """The exact D step at every grid airspeed, at the surface's gains.

        Parameters
        ----------
        surface : GainSurface
            The gains.
        omegas : ndarray of float
            Frequencies [rad/s].

        Returns
        -------
        list of MuProfile
            One per grid point.
        """
        K = surface.gain_matrix(self.airspeeds_m_s)
        return [mu_profile(m.rp, K[i], omegas) for i, m in enumerate(self.models)]

    def requirement_norms(self, surface: GainSurface) -> list[list[float]]:
        """||R_ij|| at the surface's gains, per grid point and requirement.

        Parameters
        ----------
        surface : GainSurface
            The gains.

        Returns
        -------
        list of list of float
            ``out[i][j]``.
        """
        K = surface.gain_matrix(self.airspeeds_m_s)
        return [[hinf_norm(r(K[i])).value for r in m.requirements]
                for i, m in enumerate(self.models)]


def surface_dk_problem(af: Airframe, axis: Axis, grid: Sequence[DesignPoint],
                       spec: RobustSpec = _SPEC) -> SurfaceDKProblem:
    """The robust design's N, requirements and floors at every grid airspeed.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    grid : sequence of DesignPoint
        The grid (:func:`~vtolftc.synthesis.surfaces.surface_grid`).
    spec : RobustSpec, optional
        The robust design's settings.

    Returns
    -------
    SurfaceDKProblem
        The problem.
    """
    models: list[GridModel] = []
    for p in sorted(grid, key=lambda q: q.airspeed_m_s):
        w = robust_weights(af, axis, p, spec)
        G = w.plant(af)
        reqs: list[Any] = [CascadeChannel(G, Wt=delay_weight(spec.delays.extra_margin_s))]
        if w.Wd > 0:
            reqs.append(CascadeChannel(G, Wd=disturbance_weight(w)))
        models.append(GridModel(p, cascade_rp(G, w.Ws, w.Wt, w.Wr), reqs,
                                max(1.0, float(w.Wt.gain)), w))
    u_max = min(m.weights.Wr.u_max_N_m for m in models)
    params, _ = robust_parameters(af, axis, u_max, spec)
    return SurfaceDKProblem(axis, models, params)


@dataclass(frozen=True)
class SurfaceDKStep:
    """One surface D-K iteration (iteration 0: the start, no K step).

    Parameters
    ----------
    index : int
        0, 1, 2, ...
    surface : GainSurface
        The gains after this K step.
    mu_peaks : ndarray of float, shape (n_grid,)
        Peak mu_hat (exact D step) at every grid airspeed.
    measured : float
        M = max_i mu_peaks[i] / f_i.
    scalings : tuple of RationalScaling
        The D_i(s) of the K step (empty for iteration 0).
    scaled_before, scaled_after : float
        max_i ||D_i N_i D_i^-1|| / f_i at the start and at the end of the K step (nan for
        iteration 0).
    kept_start : bool
        The tuner returned a worse J and the K step kept its start.
    message : str
        The tuner's message.
    """

    index: int
    surface: GainSurface
    mu_peaks: NDArray[np.float64]
    measured: float
    scalings: tuple[RationalScaling, ...] = ()
    scaled_before: float = math.nan
    scaled_after: float = math.nan
    kept_start: bool = False
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary (coefficients by gain, D_i(s), the measures).

        Returns
        -------
        dict of str to object
            The fields by name.
        """
        sf = self.surface
        return {"index": self.index, "degree": sf.basis.degree,
                "coefficients": {k: sf.coefficients[i].tolist()
                                 for i, k in enumerate(PARAM_NAMES)},
                "mu_peaks": self.mu_peaks.tolist(), "measured": self.measured,
                "scalings": [s.to_dict() for s in self.scalings],
                "scaled_before": self.scaled_before, "scaled_after": self.scaled_after,
                "kept_start": self.kept_start, "message": self.message}


@dataclass(frozen=True)
class SurfaceDKResult:
    """Outcome of :func:`dk_surface`.

    Parameters
    ----------
    surface : GainSurface
        The best surface (smallest M).
    measured : float
        Its M.
    steps : list of SurfaceDKStep
        Every iteration, iteration 0 first.
    stop : str
        Why the iteration stopped.
    """

    surface: GainSurface
    measured: float
    steps: list[SurfaceDKStep] = field(default_factory=list)
    stop: str = ""


def _k_step(pb: SurfaceDKProblem, surface: GainSurface, scalings: Sequence[RationalScaling],
            req_norms: Sequence[Sequence[float]], st: SurfaceDKSettings,
            ) -> tuple[GainSurface, float, float, bool, str]:
    """One multi-model K step (module docstring); returns (surface, scaled norm before,
    after, kept start, message)."""
    basis = surface.basis
    lo, hi = pb.bounds
    Phi = basis.evaluate(pb.airspeeds_m_s)
    params = coefficient_parameters(pb.gain_parameters, basis, surface)
    x0 = np.array([p.initial for p in params])
    scaled = [SurfaceChannel(ScaledChannel(m.rp, D, m.floor), Phi[i].copy(), lo, hi)
              for i, (m, D) in enumerate(zip(pb.models, scalings, strict=True))]
    before = max(hinf_norm(c(x0)).value for c in scaled)
    chans: list[Any] = [SurfaceChannel(ScaledChannel(m.rp, D, m.floor * before), Phi[i].copy(),
                                       lo, hi)
                        for i, (m, D) in enumerate(zip(pb.models, scalings, strict=True))]
    names = [f"D N D^-1 @ {v:g} m/s" for v in pb.airspeeds_m_s]
    if st.keep_requirements:
        for i, m in enumerate(pb.models):
            for j, r in enumerate(m.requirements):
                chans.append(SurfaceChannel(Normalised(r, req_norms[i][j]), Phi[i].copy(), lo,
                                            hi))
                names.append(f"req{j} @ {pb.airspeeds_m_s[i]:g} m/s")
    prob = TuningProblem(params, chans, names)
    f0 = prob.objective(x0)
    res = tune(prob, n_starts=0, max_iter=st.tune_iter)
    th = np.asarray(res.theta, float)
    kept = not (prob.objective(th) <= f0)
    if kept:
        th = x0
    after = max(hinf_norm(c(th)).value for c in scaled)
    C = th.reshape(len(PARAM_NAMES), basis.size)
    return GainSurface(basis, C, lo, hi), before, after, kept, res.message


def _measured(pb: SurfaceDKProblem, profs: Sequence[MuProfile]) -> tuple[NDArray[np.float64],
                                                                          float]:
    peaks = np.array([p.peak[0] for p in profs])
    floors = np.array([m.floor for m in pb.models])
    return peaks, float(np.max(peaks / floors))


def dk_surface(pb: SurfaceDKProblem, start: GainSurface,
               settings: SurfaceDKSettings = SurfaceDKSettings()) -> SurfaceDKResult:
    """Surface D-K iteration from ``start`` (module docstring).

    Parameters
    ----------
    pb : SurfaceDKProblem
        The grid models.
    start : GainSurface
        Starting surface (its degree is the design's); stabilising at every grid point.
    settings : SurfaceDKSettings, optional
        Iteration settings.

    Returns
    -------
    SurfaceDKResult
        The best surface by M (never worse than ``start``) and the history.

    Raises
    ------
    ValueError
        For ``max_iter`` < 1 or a start that does not stabilise every grid model.
    """
    st = settings
    if st.max_iter < 1:
        raise ValueError(f"max_iter must be >= 1, got {st.max_iter}")
    w = st.omegas()
    K0 = start.gain_matrix(pb.airspeeds_m_s)
    for i, m in enumerate(pb.models):
        A = np.asarray(m.rp(K0[i])[0])
        if A.size and float(np.max(np.linalg.eigvals(A).real)) >= 0:
            raise ValueError(f"the start does not stabilise the {pb.axis} model at "
                             f"{m.point.airspeed_m_s:g} m/s")
    req_norms = [[max(1.0, v) for v in row] for row in pb.requirement_norms(start)]
    profs = pb.profiles(start, w)
    peaks, meas = _measured(pb, profs)
    steps = [SurfaceDKStep(0, start, peaks, meas)]
    best = steps[0]
    stop = f"max_iter ({st.max_iter}) reached"
    surface = start
    for it in range(1, st.max_iter + 1):
        Ds = tuple(p.scaling(st.order) if st.scaled else RationalScaling(1.0) for p in profs)
        surface, before, after, kept, msg = _k_step(pb, surface, Ds, req_norms, st)
        profs = pb.profiles(surface, w)
        peaks, meas = _measured(pb, profs)
        step = SurfaceDKStep(it, surface, peaks, meas, Ds, before, after, kept, msg)
        steps.append(step)
        if meas < best.measured * (1.0 - st.rel_tol):
            best = step
            continue
        if meas < best.measured:
            best = step
        stop = (f"M fell by less than {st.rel_tol:.0%} (iteration {it}: {meas:.4f}, best "
                f"{best.measured:.4f})")
        break
    return SurfaceDKResult(best.surface, best.measured, steps, stop)


def dk_surfaces(pb: SurfaceDKProblem, start_gains: Mapping[str, float], degree: int = 1,
                settings: SurfaceDKSettings = SurfaceDKSettings(),
                ) -> tuple[SurfaceDKResult, SurfaceDKResult]:
    """SHIF D-K (degree 0, from ``start_gains``), then GS-SHIF D-K (``degree``, from the
    SHIF result embedded: iteration 0 of GS-SHIF is SHIF's best, so GS-SHIF's M <= SHIF's).

    Parameters
    ----------
    pb : SurfaceDKProblem
        The grid models.
    start_gains : mapping of str to float
        The constant P-PID to start from (e.g. the shipped SHIF of the axis).
    degree : int, optional
        GS-SHIF's degree, >= 1.
    settings : SurfaceDKSettings, optional
        Iteration settings (both designs).

    Returns
    -------
    shif, gs_shif : SurfaceDKResult
        The two iterations.

    Raises
    ------
    ValueError
        For ``degree`` < 1.
    """
    if degree < 1:
        raise ValueError(f"GS-SHIF degree {degree}: expected >= 1")
    shif = dk_surface(pb, pb.constant(start_gains), settings)
    gs = dk_surface(pb, shif.surface.embed(degree), settings)
    return shif, gs
