"""Validation of a gain schedule between its design points (MATLAB's gain-scheduling guide).

A schedule designed at a few airspeeds flies at every airspeed in between, with the gains the
autopilot interpolates. This module evaluates exactly that: on a grid
:data:`DEFAULT_DENSITY` (4) times denser than the design grid (every design point and three
evenly spaced airspeeds in each design interval: ``4 (n - 1) + 1`` points), per axis,

- the gains **as flown**: :class:`FlownSchedule` interpolates the gain-schedule document
  with the same arithmetic as the autopilot's
  :meth:`vtolftc.firmware_sim.autopilot.schedule.GainSchedule.gains_at` (piecewise linear,
  clamped outside the breakpoints; a test checks the two agree bit for bit). A gain surface
  is validated through the document it is exported to (what flies is the document);
- the plant linearised **at that airspeed**: the robust design's plant
  (:func:`vtolftc.synthesis.robust.design_plant`: eq. 1-3 behind the actuator lag with the
  8 ms loop delay folded in), nominal effectiveness (gamma = 0);
- closed-loop **stability**: the largest real part of the closed-loop poles [rad/s];
- **margins** of the loop broken at the actuator (plant input), L_u = K_rate (kp_angle
  G_angle + G_rate): gain margins (upper and lower), phase margin and delay margin
  (:func:`loop_margins_classical`, tested against ``control.stability_margins``);
- **robust stability mu**: the lumped complex mu_RS of the paper's table 3 (eq. 13, the
  robust design's weights evaluated at that airspeed and the perturbed range interpolated
  between the design points' ranges, :func:`vtolftc.synthesis.robustness.analyse`), and the
  real-parametric **mixed-mu** upper bound of :mod:`vtolftc.synthesis.certificate`.

The mixed-mu certificate over the continuous airspeed range
-----------------------------------------------------------
Airspeed is treated as a **real parametric uncertainty within each grid cell** for the
plant, and covered by a **finite-difference continuity estimate** for the gains. The grid
points' cells [c_lo, c_hi] (halfway to each neighbour; the first and last end at the grid
ends) tile the whole range with no gap. In each cell, the certificate's exact LFT of the
plant family (V in the cell, gamma in [0, 0.6], :func:`vtolftc.synthesis.certificate.family`)
is closed with the gains of the grid point and its mixed-mu upper bound mu_c is computed:
mu_c < 1 *proves* robust stability of every frozen plant in the cell with those gains. This
is chosen over a Lipschitz bound of the frequency response for the plant because the LFT is
exact (the derivative tables are piecewise linear in V) and costs no more than a point.

The flown gains are not frozen across the cell: they move linearly (piecewise, with a kink
at a design point) from theta(c_lo) to theta(c_hi). Putting them in the LFT too would need
the controller realised as a polynomial in dV; instead the bound is also computed with the
gains at the two cell ends, against the same plant family, and the gap is covered by a
Lipschitz estimate: with samples at c_lo, V_i, c_hi, every airspeed in a half cell is
within a quarter cell of a sample, so the bound over the cell is estimated as

    mu_cell = max(mu(c_lo), mu_c, mu(c_hi)) + max |mu(end) - mu_c| / 2,

(the Lipschitz constant in airspeed by finite differences, times the largest distance to a
sample). ``mu_cell < 1`` is the certificate over the continuous range. The plant part is
proved; the gain part is an estimate (it assumes the bound varies no faster between samples
than across them), which the dense grid makes small: a 4x grid cell is an eighth of a design
interval.

Failures
--------
A grid point fails (:class:`Requirements`) when its loop is unstable, a margin is below the
requirement, mu_RS >= 1 or the mixed-mu cell bound >= 1. :attr:`ValidationResult.failures`
lists each with the reason; ``between`` tells whether it lies strictly between design
points (what interpolation adds) or at one (what the design already had).
"""

from __future__ import annotations

import bisect
import itertools
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.export import write_json
from vtolftc.synthesis.loops import PARAM_NAMES, closed_loop
from vtolftc.synthesis.models import AXES, Axis
from vtolftc.synthesis.uncertainty import DesignPoint

__all__ = [
    "DEFAULT_DENSITY",
    "ClassicalMargins",
    "FlownSchedule",
    "GridPointResult",
    "Requirements",
    "ValidationPlan",
    "ValidationResult",
    "cell_bounds",
    "dense_grid",
    "design_grid",
    "loop_margins_classical",
    "plan_validation",
    "validate_job",
    "validate_point",
    "validate_schedule",
]

#: Grid intervals per design interval of the validation grid (MATLAB's guide: "denser").
DEFAULT_DENSITY = 4
#: Frequencies where the loop's crossings are searched [rad/s].
MARGIN_OMEGAS = np.logspace(-3, 4, 3000)


# ------------------------------------------------------------------------------------------
# the schedule as the autopilot flies it
# ------------------------------------------------------------------------------------------


class FlownSchedule:
    """The gains of a ``vtolftc-gain-schedule/1`` document as the autopilot interpolates them.

    The arithmetic is that of ``GainSchedule.gains_at`` (the synthesis layer cannot import
    the autopilot): for V strictly inside [V_i, V_{i+1}), ``w = (V - V_i) / (V_{i+1} - V_i)``
    and each gain is ``a + w (b - a)``; at or below the first breakpoint (or NaN) the first
    breakpoint's gains, at or above the last the last's.

    Parameters
    ----------
    doc : mapping
        The parsed gain-schedule document (``airspeed_breakpoints_m_s``, ``axes``: all three
        axes or a subset; :meth:`gains_at` knows those given).

    Examples
    --------
    >>> g = {k: [1.0, 3.0] for k in PARAM_NAMES}
    >>> s = FlownSchedule({"airspeed_breakpoints_m_s": [0.0, 10.0],
    ...                    "axes": {ax: g for ax in AXES}})
    >>> s.gains_at("roll", 2.5)["kp_rate"], s.gains_at("roll", 99.0)["kp_rate"]
    (1.5, 3.0)
    """

    def __init__(self, doc: Mapping[str, Any]) -> None:
        self.breakpoints_m_s: tuple[float, ...] = tuple(
            float(v) for v in doc["airspeed_breakpoints_m_s"])
        self.table: dict[str, list[tuple[float, ...]]] = {
            ax: [tuple(float(doc["axes"][ax][k][i]) for k in PARAM_NAMES)
                 for i in range(len(self.breakpoints_m_s))]
            for ax in AXES if ax in doc["axes"]}
        self._bp = list(self.breakpoints_m_s)

    def gains_at(self, axis: Axis, airspeed_m_s: float) -> dict[str, float]:
        """The gains of ``axis`` at an airspeed, as flown.

        Parameters
        ----------
        axis : {"roll", "pitch", "yaw"}
            The axis.
        airspeed_m_s : float
            Airspeed [m/s].

        Returns
        -------
        dict of str to float
            :data:`~vtolftc.synthesis.loops.PARAM_NAMES` -> gain (SI units).
        """
        bp, rows, V = self._bp, self.table[axis], airspeed_m_s
        if not bp[0] < V:  # also NaN
            return dict(zip(PARAM_NAMES, rows[0], strict=True))
        if bp[-1] <= V:
            return dict(zip(PARAM_NAMES, rows[-1], strict=True))
        i = bisect.bisect_right(bp, V) - 1
        w = (V - bp[i]) / (bp[i + 1] - bp[i])
        if w == 0.0:
            return dict(zip(PARAM_NAMES, rows[i], strict=True))
        r, s = rows[i], rows[i + 1]
        return dict(zip(PARAM_NAMES, (a + w * (b - a) for a, b in zip(r, s, strict=True)),
                        strict=True))


def design_grid(doc: Mapping[str, Any]) -> tuple[DesignPoint, ...]:
    """The design points of a schedule document.

    Its ``design_points`` metadata when present (point number, airspeed and perturbed
    range), else one point per breakpoint with the range reaching halfway to each
    neighbour.

    Parameters
    ----------
    doc : mapping
        The parsed gain-schedule document.

    Returns
    -------
    tuple of DesignPoint
        By increasing airspeed.
    """
    if doc.get("design_points"):
        pts = [DesignPoint(int(p["number"]), float(p["airspeed_m_s"]), float(p["v_min_m_s"]),
                           float(p["v_max_m_s"])) for p in doc["design_points"]]
        return tuple(sorted(pts, key=lambda p: p.airspeed_m_s))
    bps = [float(v) for v in doc["airspeed_breakpoints_m_s"]]
    lo, hi = cell_bounds(bps)
    return tuple(DesignPoint(i + 1, v, a, b)
                 for i, (v, a, b) in enumerate(zip(bps, lo, hi, strict=True)))


def dense_grid(points: Sequence[DesignPoint], density: int = DEFAULT_DENSITY,
               ) -> tuple[DesignPoint, ...]:
    """The validation grid: every design point and ``density - 1`` evenly spaced airspeeds in
    each design interval, ``density (n - 1) + 1`` points.

    Each grid point carries a perturbed range interpolated between its design points' ranges
    (for the weights of the lumped mu), as :func:`vtolftc.synthesis.surfaces.surface_grid`.

    Parameters
    ----------
    points : sequence of DesignPoint
        The design points (at least two).
    density : int
        Grid intervals per design interval (>= 1).

    Returns
    -------
    tuple of DesignPoint
        By increasing airspeed.
    """
    from vtolftc.synthesis.surfaces import surface_grid

    return surface_grid(points, density)


def cell_bounds(airspeeds_m_s: Sequence[float]) -> tuple[list[float], list[float]]:
    """The cells of a grid: from halfway to the previous point to halfway to the next (the
    first cell starts at the first point, the last ends at the last). They tile
    [V_0, V_n] without gaps.

    Parameters
    ----------
    airspeeds_m_s : sequence of float
        Strictly increasing grid airspeeds [m/s].

    Returns
    -------
    lo, hi : list of float
        Cell bounds [m/s].

    Examples
    --------
    >>> cell_bounds([0.0, 1.0, 3.0])
    ([0.0, 0.5, 2.0], [0.5, 2.0, 3.0])
    """
    v = [float(x) for x in airspeeds_m_s]
    mids = [0.5 * (a + b) for a, b in itertools.pairwise(v)]
    return [v[0], *mids], [*mids, v[-1]]


# ------------------------------------------------------------------------------------------
# margins
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ClassicalMargins:
    """Gain, phase and delay margins of a SISO loop L (negative feedback).

    Parameters
    ----------
    gain_margin : float
        The gain margin closest to 1 on a log scale, python-control's convention (factor,
        dimensionless; inf if the phase never crosses -180 deg).
    gain_margin_upper : float
        Smallest factor > 1 at a phase crossover: the gain increase that destabilises
        (inf if none).
    gain_margin_lower : float
        Largest factor < 1 at a phase crossover: the gain reduction that destabilises a
        conditionally stable loop (0 if none).
    phase_crossover_rad_s : float
        Frequency of ``gain_margin`` [rad/s] (nan if none).
    phase_margin_deg : float
        The phase margin of smallest magnitude over the gain crossovers [deg], in
        (-180, 180] (inf if |L| never crosses 1).
    gain_crossover_rad_s : float
        Frequency of ``phase_margin_deg`` [rad/s] (nan if none).
    delay_margin_s : float
        Smallest extra loop delay that destabilises: min over the gain crossovers w_c of
        PM(w_c) / w_c, PM taken in [0, 2 pi) [s] (inf if no crossover).
    stability_margin : float
        min over frequency of |1 + L| (dimensionless).
    """

    gain_margin: float
    gain_margin_upper: float
    gain_margin_lower: float
    phase_crossover_rad_s: float
    phase_margin_deg: float
    gain_crossover_rad_s: float
    delay_margin_s: float
    stability_margin: float

    @property
    def gain_margin_upper_db(self) -> float:
        """``gain_margin_upper`` in dB (inf if none)."""
        return _db(self.gain_margin_upper)

    @property
    def gain_margin_lower_db(self) -> float:
        """``gain_margin_lower`` in dB (negative; -inf if none)."""
        return _db(self.gain_margin_lower)


def _db(x: float) -> float:
    if x <= 0.0:
        return -math.inf
    return 20.0 * math.log10(x) if math.isfinite(x) else math.inf


def loop_margins_classical(L: Callable[[NDArray[np.float64]], NDArray[np.complex128]],
                           omegas: NDArray[np.float64] | None = None) -> ClassicalMargins:
    """Gain, phase and delay margins of the loop ``L`` from its frequency response.

    Crossings are bracketed on the grid and refined by Brent's method on ``L`` itself:
    phase crossovers where Im L changes sign with Re L < 0, gain crossovers where |L| - 1
    does.

    Parameters
    ----------
    L : callable
        ``L(omegas)`` -> complex frequency response at ``omegas`` [rad/s] (vectorised).
    omegas : ndarray of float, optional
        The search grid [rad/s] (default :data:`MARGIN_OMEGAS`, 1e-3 .. 1e4 rad/s).

    Returns
    -------
    ClassicalMargins
        The margins.

    Examples
    --------
    >>> m = loop_margins_classical(lambda w: 4.0 / (1j * w + 1.0) ** 3)
    >>> round(m.gain_margin, 6), round(m.phase_crossover_rad_s ** 2, 6)
    (2.0, 3.0)
    """
    w = MARGIN_OMEGAS if omegas is None else np.asarray(omegas, float)
    Lw = np.asarray(L(w), complex)

    def one(x: float) -> complex:
        return complex(np.asarray(L(np.array([x])), complex)[0])

    # phase crossovers: Im L = 0 with Re L < 0
    gms: list[tuple[float, float]] = []
    im = Lw.imag
    for i in np.nonzero(np.sign(im[:-1]) * np.sign(im[1:]) <= 0)[0]:
        if im[i] == 0.0 and i > 0 and im[i - 1] == 0.0:
            continue
        a, b = w[i], w[i + 1]
        wp = a if im[i] == 0.0 else (b if im[i + 1] == 0.0 else
                                     brentq(lambda x: one(x).imag, a, b, xtol=1e-14,
                                            rtol=1e-12))
        v = one(wp)
        if v.real < 0.0:
            gms.append((1.0 / abs(v), wp))
    # gain crossovers
    pms: list[tuple[float, float]] = []
    mg = np.abs(Lw) - 1.0
    for i in np.nonzero(np.sign(mg[:-1]) * np.sign(mg[1:]) < 0)[0]:
        wc = brentq(lambda x: abs(one(x)) - 1.0, w[i], w[i + 1], xtol=1e-14, rtol=1e-12)
        pm = math.degrees(math.atan2(one(wc).imag, one(wc).real)) % 360.0 - 180.0
        pms.append((pm, wc))
    if gms:
        gm, wg = min(gms, key=lambda t: abs(math.log(t[0])) if t[0] > 0 else math.inf)
        ups = [g for g, _ in gms if g > 1.0]
        los = [g for g, _ in gms if g < 1.0]
        gm_up = min(ups) if ups else math.inf
        gm_lo = max(los) if los else 0.0
    else:
        gm, wg, gm_up, gm_lo = math.inf, math.nan, math.inf, 0.0
    if pms:
        pm, wc = min(pms, key=lambda t: abs(t[0]))
        dm = min(math.radians(p % 360.0) / c for p, c in pms)
    else:
        pm, wc, dm = math.inf, math.nan, math.inf
    return ClassicalMargins(float(gm), float(gm_up), float(gm_lo), float(wg), float(pm),
                            float(wc), float(dm), float(np.min(np.abs(1.0 + Lw))))


# ------------------------------------------------------------------------------------------
# one grid point
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Requirements:
    """What a grid point must meet.

    Parameters
    ----------
    gain_margin_db : float
        Smallest upper gain margin [dB] (and the lower one at most minus this, when the
        loop is conditionally stable).
    phase_margin_deg : float
        Smallest |phase margin| [deg].
    delay_margin_s : float
        Smallest delay margin [s] (default: the robust design's 50 ms extra-delay
        requirement, :class:`vtolftc.synthesis.robust.LoopDelays`).
    mu : float
        mu_RS and the mixed-mu cell bound must be below this.
    """

    gain_margin_db: float = 6.0
    phase_margin_deg: float = 30.0
    delay_margin_s: float = 0.050
    mu: float = 1.0


@dataclass
class GridPointResult:
    """The validation of one axis at one grid airspeed.

    Parameters
    ----------
    axis : str
        The axis.
    airspeed_m_s : float
        The grid airspeed [m/s].
    design_point : bool
        Whether it is a design point.
    cell_m_s : (float, float)
        Its cell of the continuous range [m/s].
    gains : dict of str to float
        The gains as flown there.
    max_real_pole_rad_s : float
        Largest real part of the nominal closed-loop poles [rad/s] (< 0: stable).
    margins : ClassicalMargins or None
        Loop broken at the actuator (None if unstable).
    mu_rs : float or None
        Lumped complex robust-stability mu (table 3 form; None if not computed).
    mu_rp : float or None
        Lumped robust-performance mu (table 3 form; recorded, not a requirement).
    mixed_mu_upper : float or None
        Mixed-mu upper bound over the cell with the grid point's gains (proved).
    mixed_mu_lower : float or None
        Its verified lower bound.
    mixed_mu_ends : (float, float) or None
        The upper bound with the gains at the cell's two ends.
    mixed_mu_cell : float or None
        The estimated bound over the cell with the flown gains (module docstring).
    failures : list of str
        Why it fails the requirements (empty: passes).
    """

    axis: str
    airspeed_m_s: float
    design_point: bool
    cell_m_s: tuple[float, float]
    gains: dict[str, float]
    max_real_pole_rad_s: float
    margins: ClassicalMargins | None = None
    mu_rs: float | None = None
    mu_rp: float | None = None
    mixed_mu_upper: float | None = None
    mixed_mu_lower: float | None = None
    mixed_mu_ends: tuple[float, float] | None = None
    mixed_mu_cell: float | None = None
    failures: list[str] = field(default_factory=list)

    @property
    def stable(self) -> bool:
        """Nominal closed-loop stability."""
        return self.max_real_pole_rad_s < 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (inf and nan as None).

        Returns
        -------
        dict
            Every field, margins flattened with their dB forms.
        """
        d: dict[str, Any] = {k: v for k, v in self.__dict__.items() if k != "margins"}
        d["stable"] = self.stable
        if self.margins is not None:
            m = asdict(self.margins)
            m["gain_margin_upper_db"] = self.margins.gain_margin_upper_db
            m["gain_margin_lower_db"] = self.margins.gain_margin_lower_db
            d["margins"] = m
        else:
            d["margins"] = None
        return _clean(d)


def _clean(x: Any) -> Any:
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    return x


def _sweep_peak(af: Airframe, axis: Axis, lo: float, hi: float, theta: Any,
                seed: int = 0) -> float:
    """Mixed-mu upper peak over the cell [lo, hi] with frozen gains ``theta`` (max over the
    cell's table pieces; inf if a piece's centre is unstable)."""
    from vtolftc.synthesis.certificate import (
        airspeed_pieces,
        family,
        mu_real_sweep,
        true_closed_loop_matrices,
    )

    peak = 0.0
    for a, b in airspeed_pieces(af, DesignPoint(0, lo, lo, hi)):
        fam = family(af, axis, a, b)
        A = true_closed_loop_matrices(fam.inertia, *fam.coefficients(0.0, 0.0), fam.tau_s,
                                      theta)[0]
        if np.linalg.eigvals(A).real.max() >= 0.0:
            return math.inf
        peak = max(peak, mu_real_sweep(fam, theta, seed=seed).peak_upper)
    return peak


def validate_point(af: Airframe, axis: Axis, point: DesignPoint, cell: tuple[float, float],
                   schedule: FlownSchedule, *, design_point: bool = False, mu: bool = True,
                   certificate: bool = True, requirements: Requirements = Requirements(),
                   grid_n: int = 21, seed: int = 0) -> GridPointResult:
    """Validate one axis at one grid point (see the module docstring).

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    point : DesignPoint
        The grid point (airspeed, and the perturbed range for the lumped mu's weights).
    cell : (float, float)
        Its cell of the continuous range [m/s] (:func:`cell_bounds`).
    schedule : FlownSchedule
        The schedule.
    design_point : bool
        Whether the grid point is a design point (recorded only).
    mu : bool
        Compute the lumped complex mu_RS.
    certificate : bool
        Compute the mixed-mu bounds over the cell.
    requirements : Requirements
        The requirements.
    grid_n : int
        Grid points per parameter of the certificate's dense (V, gamma) grid.
    seed : int
        Seed of the random lower-bound starts.

    Returns
    -------
    GridPointResult
        The row.
    """
    from vtolftc.synthesis.robust import design_plant, loop_frequency_response

    V = point.airspeed_m_s
    theta = schedule.gains_at(axis, V)
    G = design_plant(af, axis, V)
    pmax = float(np.max(closed_loop(G, theta).poles.real))
    r = GridPointResult(axis, V, design_point, (float(cell[0]), float(cell[1])), theta, pmax)
    req = requirements
    if not r.stable:
        r.failures.append(f"unstable (max real pole {pmax:.3g} rad/s)")
        return r
    m = loop_margins_classical(lambda w: loop_frequency_response(G, theta, w))
    r.margins = m
    if m.gain_margin_upper_db < req.gain_margin_db:
        r.failures.append(f"gain margin {m.gain_margin_upper_db:.2f} dB < "
                          f"{req.gain_margin_db:g} dB")
    if m.gain_margin_lower > 0.0 and m.gain_margin_lower_db > -req.gain_margin_db:
        r.failures.append(f"lower gain margin {m.gain_margin_lower_db:.2f} dB > "
                          f"-{req.gain_margin_db:g} dB")
    if abs(m.phase_margin_deg) < req.phase_margin_deg:
        r.failures.append(f"phase margin {m.phase_margin_deg:.1f} deg < "
                          f"{req.phase_margin_deg:g} deg")
    if m.delay_margin_s < req.delay_margin_s:
        r.failures.append(f"delay margin {1e3 * m.delay_margin_s:.1f} ms < "
                          f"{1e3 * req.delay_margin_s:g} ms")
    if mu:
        from vtolftc.synthesis.robust import robust_weights
        from vtolftc.synthesis.robustness import analyse

        wts = robust_weights(af, axis, point)
        try:
            an = analyse(wts.plant(af), theta, wts.Ws, wts.Wt, wts.Wr, seed=seed)
            r.mu_rs, r.mu_rp = float(an.mu_rs), float(an.mu_rp)
        except ValueError:  # the centred nominal is unstable: mu is infinite
            r.mu_rs = r.mu_rp = math.inf
        if not r.mu_rs < req.mu:
            r.failures.append(f"mu_RS {r.mu_rs:.3f} >= {req.mu:g}")
    if certificate:
        from vtolftc.synthesis.certificate import certify_point

        lo, hi = r.cell_m_s
        c = certify_point(af, axis, DesignPoint(point.number, V, lo, hi), theta, "lagged",
                          grid_n=grid_n, seed=seed, margin=False)
        r.mixed_mu_upper, r.mixed_mu_lower = float(c.mu_upper), float(c.mu_lower)
        ends = tuple(_sweep_peak(af, axis, lo, hi, schedule.gains_at(axis, e), seed)
                     if e != V else r.mixed_mu_upper for e in (lo, hi))
        r.mixed_mu_ends = (float(ends[0]), float(ends[1]))
        samples = [ends[0], r.mixed_mu_upper, ends[1]]
        r.mixed_mu_cell = float(max(samples) + max(abs(e - r.mixed_mu_upper)
                                                   for e in ends) / 2.0)
        if not c.grid.stable:
            r.failures.append(f"unstable member of the (V, gamma) grid of the cell at "
                              f"V {c.grid.worst_airspeed_m_s:.3g} m/s, gamma "
                              f"{c.grid.worst_gamma:.3g}")
        if not r.mixed_mu_cell < req.mu:
            r.failures.append(f"mixed mu over the cell {r.mixed_mu_cell:.3f} >= {req.mu:g} "
                              f"(frozen gains {r.mixed_mu_upper:.3f})")
    return r


# ------------------------------------------------------------------------------------------
# the schedule
# ------------------------------------------------------------------------------------------


@dataclass
class ValidationResult:
    """The validation table of a schedule.

    Parameters
    ----------
    controller : str
        The schedule's controller name.
    design_airspeeds_m_s : list of float
        The design grid [m/s].
    density : int
        Grid intervals per design interval.
    rows : list of GridPointResult
        One per axis and grid point (axis-major, by airspeed).
    requirements : Requirements
        What was required.
    grid_m_s : list of float
        The whole validation grid [m/s] (``rows`` may hold a slice of it).
    """

    controller: str
    design_airspeeds_m_s: list[float]
    density: int
    rows: list[GridPointResult]
    requirements: Requirements
    grid_m_s: list[float]

    @property
    def failures(self) -> list[GridPointResult]:
        """Rows that fail a requirement."""
        return [r for r in self.rows if r.failures]

    @property
    def failures_between(self) -> list[GridPointResult]:
        """Failing rows strictly between design points."""
        return [r for r in self.failures if not r.design_point]

    def summary(self) -> dict[str, Any]:
        """Per axis: the worst numbers over the grid and the failure counts.

        Returns
        -------
        dict
            ``{axis: {max_real_pole_rad_s, min_gain_margin_db, min_phase_margin_deg,
            min_delay_margin_s, max_mu_rs, max_mixed_mu_upper, max_mixed_mu_cell,
            failures, failures_between}}`` (None where not computed).
        """
        out: dict[str, Any] = {}
        for ax in AXES:
            rows = [r for r in self.rows if r.axis == ax]
            if not rows:
                continue
            ms = [r.margins for r in rows if r.margins is not None]

            def mx(vals: list[float | None]) -> float | None:
                v = [x for x in vals if x is not None]
                return max(v) if v else None

            out[ax] = {
                "max_real_pole_rad_s": max(r.max_real_pole_rad_s for r in rows),
                "min_gain_margin_db": min((m.gain_margin_upper_db for m in ms),
                                          default=None),
                "min_phase_margin_deg": min((abs(m.phase_margin_deg) for m in ms),
                                            default=None),
                "min_delay_margin_s": min((m.delay_margin_s for m in ms), default=None),
                "max_mu_rs": mx([r.mu_rs for r in rows]),
                "max_mixed_mu_upper": mx([r.mixed_mu_upper for r in rows]),
                "max_mixed_mu_cell": mx([r.mixed_mu_cell for r in rows]),
                "failures": sum(bool(r.failures) for r in rows),
                "failures_between": sum(bool(r.failures) and not r.design_point
                                        for r in rows),
            }
        return _clean(out)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: settings, summary, rows.

        Returns
        -------
        dict
            The document written by :meth:`write`.
        """
        return {"format": "vtolftc-schedule-validation/1", "controller": self.controller,
                "design_airspeeds_m_s": self.design_airspeeds_m_s, "density": self.density,
                "grid_m_s": self.grid_m_s, "requirements": asdict(self.requirements),
                "continuity": "plant: V a real parameter in each grid cell (exact LFT, "
                              "proved); gains: bound at the cell ends, Lipschitz estimate",
                "summary": self.summary(),
                "rows": [r.to_dict() for r in self.rows]}

    def write(self, path: str | Path) -> Path:
        """Write :meth:`to_dict` as JSON (atomically).

        Parameters
        ----------
        path : str or pathlib.Path
            The file.

        Returns
        -------
        pathlib.Path
            The file written.
        """
        return write_json(Path(path), json.loads(json.dumps(self.to_dict())))


def validate_job(j: tuple[Any, ...]) -> GridPointResult:
    """Run one job of :attr:`ValidationPlan.jobs` (picklable, for worker processes).

    Parameters
    ----------
    j : tuple
        The job.

    Returns
    -------
    GridPointResult
        Its row.
    """
    af, ax, p, cell, sched, is_dp, mu, cert, req, grid_n, seed = j
    return validate_point(af, ax, p, cell, sched, design_point=is_dp, mu=mu,
                          certificate=cert, requirements=req, grid_n=grid_n, seed=seed)


@dataclass(frozen=True)
class ValidationPlan:
    """The axis-point jobs of a validation and how their rows make the table.

    Parameters
    ----------
    controller : str
        The schedule's controller name.
    points : tuple of DesignPoint
        The design grid.
    grid : tuple of DesignPoint
        The dense validation grid.
    density : int
        Grid intervals per design interval.
    requirements : Requirements
        What each grid point must meet.
    jobs : list of tuple
        One :func:`validate_job` argument per axis and grid point (axis-major, by airspeed).
    """

    controller: str
    points: tuple[DesignPoint, ...]
    grid: tuple[DesignPoint, ...]
    density: int
    requirements: Requirements
    jobs: list[tuple[Any, ...]]

    def result(self, rows: Sequence[GridPointResult]) -> ValidationResult:
        """The table of the jobs' rows.

        Parameters
        ----------
        rows : sequence of GridPointResult
            The rows, in the order of :attr:`jobs`.

        Returns
        -------
        ValidationResult
            The table.
        """
        return ValidationResult(self.controller, [p.airspeed_m_s for p in self.points],
                                self.density, list(rows), self.requirements,
                                [p.airspeed_m_s for p in self.grid])


def plan_validation(af: Airframe, doc: Mapping[str, Any], *,
                    density: int = DEFAULT_DENSITY,
                    points: Sequence[DesignPoint] | None = None,
                    axes: Sequence[Axis] = AXES, mu: bool = True, certificate: bool = True,
                    requirements: Requirements = Requirements(), grid_n: int = 21,
                    seed: int = 0, airspeeds_m_s: Sequence[float] | None = None,
                    ) -> ValidationPlan:
    """The jobs of :func:`validate_schedule`, to run in any order or pool.

    Parameters
    ----------
    af : Airframe
        The airframe the schedule is for.
    doc : mapping
        The parsed gain-schedule document; it needs only the ``axes`` validated
        (:class:`FlownSchedule`).
    density, points, axes, mu, certificate, requirements, grid_n, seed, airspeeds_m_s
        As in :func:`validate_schedule`.

    Returns
    -------
    ValidationPlan
        The jobs and the table they make.
    """
    pts = tuple(points) if points is not None else design_grid(doc)
    grid = dense_grid(pts, density)
    lo, hi = cell_bounds([p.airspeed_m_s for p in grid])
    design_vs = {p.airspeed_m_s for p in pts}
    sched = FlownSchedule(doc)
    keep = None if airspeeds_m_s is None else {float(v) for v in airspeeds_m_s}
    jobs_list = [(af, ax, p, (a, b), sched, p.airspeed_m_s in design_vs, mu, certificate,
                  requirements, grid_n, seed)
                 for ax in axes for p, a, b in zip(grid, lo, hi, strict=True)
                 if keep is None or p.airspeed_m_s in keep]
    return ValidationPlan(str(doc.get("controller", "")), pts, grid, density, requirements,
                          jobs_list)


def validate_schedule(af: Airframe, doc: Mapping[str, Any], *,
                      density: int = DEFAULT_DENSITY,
                      points: Sequence[DesignPoint] | None = None,
                      axes: Sequence[Axis] = AXES, mu: bool = True, certificate: bool = True,
                      requirements: Requirements = Requirements(), grid_n: int = 21,
                      seed: int = 0, airspeeds_m_s: Sequence[float] | None = None,
                      progress: Callable[[str], None] | None = None,
                      jobs: int = 1) -> ValidationResult:
    """Validate a gain-schedule document on the dense grid (see the module docstring).

    Parameters
    ----------
    af : Airframe
        The airframe the schedule is for.
    doc : mapping
        The parsed ``vtolftc-gain-schedule/1`` document (e.g. ``gs-shif.json``).
    density : int
        Grid intervals per design interval (default 4).
    points : sequence of DesignPoint, optional
        The design grid (default :func:`design_grid` of the document).
    axes : sequence of str
        The axes to validate.
    mu, certificate : bool
        Compute the lumped mu_RS / the mixed-mu cell bounds.
    requirements : Requirements
        What each grid point must meet.
    grid_n : int
        The certificate's (V, gamma) grid size per parameter.
    seed : int
        Seed of the random lower-bound starts.
    airspeeds_m_s : sequence of float, optional
        Validate only the grid points at these airspeeds (a slice; their cells are still
        those of the whole grid).
    progress : callable, optional
        Called with a label after each axis-point.
    jobs : int
        Worker processes (1: in this process); the rows are the same either way.

    Returns
    -------
    ValidationResult
        The table.
    """
    plan = plan_validation(af, doc, density=density, points=points, axes=axes, mu=mu,
                           certificate=certificate, requirements=requirements,
                           grid_n=grid_n, seed=seed, airspeeds_m_s=airspeeds_m_s)
    jobs_list = plan.jobs
    rows: list[GridPointResult] = []
    if jobs > 1 and len(jobs_list) > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(min(jobs, len(jobs_list))) as ex:
            futs = [ex.submit(validate_job, j) for j in jobs_list]
            for j, f in zip(jobs_list, futs, strict=True):
                rows.append(f.result())
                if progress is not None:
                    progress(f"validation {j[1]} {j[2].airspeed_m_s:g} m/s")
    else:
        for j in jobs_list:
            rows.append(validate_job(j))
            if progress is not None:
                progress(f"validation {j[1]} {j[2].airspeed_m_s:g} m/s")
    return plan.result(rows)
