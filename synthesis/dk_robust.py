"""D-K iteration (:mod:`vtolftc.synthesis.dk`) applied to the robust point design
(:mod:`vtolftc.synthesis.robust`): ``vtolftc synth --dk N`` and ``benchmarks/bench_dk.py``.

Per axis and design point, from the robust design's gains:

- **N** is paper eq. 14 on the robust design plant at the centred nominal (actuator lag and
  loop delay included): uncertainty channel z = W_t u -> d (W_t the multiplicative input
  cover of the point's airspeed range x gamma in [0, 0.6] about the centred nominal: the
  fault set), performance [Ws e; Wr u] from the reference r (Ws the robust rule's
  sensitivity weight, omega_b and M of :func:`~vtolftc.synthesis.robust.sensitivity_rule`;
  Wr eq. 6 with the point's authority). mu_RP < 1 means: for every plant of the fault set
  the weighted tracking and control-effort requirement ||[Ws S; Wr R]|| < 1 holds.
- **Requirements kept in the K step** (never worse than the robust design, at most 1 where it
  met them): the delay-margin channel ||W_delta T_u||_inf (50 ms, small gain) and the
  rotor-out disturbance channel ||Wd e/d||_inf of :mod:`~vtolftc.synthesis.robust`.
- **Gain bounds** those of :func:`~vtolftc.synthesis.robust.robust_parameters` (actuator
  bandwidth, gyro noise).

Reported before/after (:class:`DKPoint`): mu_RS and mu_RP (:func:`vtolftc.synthesis.robustness.
analyse`, mu_sweep's upper and lower bounds, independent of the D-K code), the exact delay
margin (:func:`~vtolftc.synthesis.robust.loop_margins`) and the requirement norms.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.dk import DKResult, cascade_rp, dk_iterate
from vtolftc.synthesis.loops import PARAM_NAMES, CascadeChannel
from vtolftc.synthesis.models import Axis
from vtolftc.synthesis.robust import (
    RobustSpec,
    delay_weight,
    disturbance_weight,
    loop_margins,
    robust_parameters,
    robust_weights,
)
from vtolftc.synthesis.robustness import analyse
from vtolftc.synthesis.uncertainty import DesignPoint

__all__ = ["DKPoint", "DKSettings", "dk_point", "dk_schedule"]


@dataclass(frozen=True)
class DKSettings:
    """Settings of the D-K iteration of one axis-point.

    Parameters
    ----------
    max_iter : int, optional
        Maximum D-K iterations (K steps).
    order : {0, 1, 2}, optional
        Order of the fitted D(s).
    rel_tol : float, optional
        Stop when the peak mu_RP falls by less than this fraction.
    tune_iter : int, optional
        Iteration cap of each K step's tune.
    keep_requirements : bool, optional
        Keep the delay-margin and rotor-out channels in the K step (False: robust
        performance alone, a diagnostic of what the structure can reach on mu_RP).
    """

    max_iter: int = 4
    order: int = 2
    rel_tol: float = 0.01
    tune_iter: int = 40
    keep_requirements: bool = True

    def to_dict(self) -> dict[str, Any]:
        """The settings as a JSON-ready dict.

        Returns
        -------
        dict of str to object
            The fields by name.
        """
        return dict(self.__dict__)


#: The robust design's default settings (DS-1's declared requirements).
_SPEC = RobustSpec()


@dataclass(frozen=True)
class DKPoint:
    """Before/after of one axis-point.

    Parameters
    ----------
    axis : {"roll", "pitch", "yaw"}
        The attitude axis.
    point : int
        Design point number.
    airspeed_m_s : float
        Its airspeed [m/s].
    before, after : dict of str to float
        ``mu_rs``, ``mu_rp``, ``mu_rp_lower``, ``mu_rp_peak_frequency_rad_s``,
        ``delay_margin_s``, ``Wdelay*T``, ``Wd*Sd`` (0 without a rotor-out moment) of the
        starting and the D-K gains.
    gains_before, gains_after : dict of str to float
        The P-PID gains (:data:`~vtolftc.synthesis.loops.PARAM_NAMES`, units there).
    dk : DKResult
        The iteration's history.
    """

    axis: Axis
    point: int
    airspeed_m_s: float
    before: dict[str, float]
    after: dict[str, float]
    gains_before: dict[str, float]
    gains_after: dict[str, float]
    dk: DKResult

    def to_dict(self) -> dict[str, Any]:
        """Everything as a JSON-ready dict.

        Returns
        -------
        dict of str to object
            Axis, point, airspeed [m/s], before/after measures, gains and the iterations.
        """
        return {"axis": self.axis, "point": self.point, "airspeed_m_s": self.airspeed_m_s,
                "before": self.before, "after": self.after,
                "gains_before": self.gains_before, "gains_after": self.gains_after,
                "iterations": [s.to_dict() for s in self.dk.steps], "stop": self.dk.stop}


def _measure(af: Airframe, w: Any, reqs: Sequence[Any], theta: np.ndarray) -> dict[str, float]:
    from vtolftc.synthesis.hinfnorm import hinf_norm

    G = w.plant(af)
    a = analyse(G, theta, w.Ws, w.Wt, w.Wr)
    out = {"mu_rs": a.mu_rs, "mu_rp": a.mu_rp, "mu_rp_lower": a.rp.peak_lower,
           "mu_rp_peak_frequency_rad_s": a.rp.peak_upper_frequency_rad_s,
           "delay_margin_s": loop_margins(G, theta).delay_margin_s}
    names = ["Wdelay*T", "Wd*Sd"]
    for nm, r in zip(names, reqs, strict=False):
        out[nm] = hinf_norm(r(theta)).value
    out.setdefault("Wd*Sd", 0.0)
    return out


def dk_point(af: Airframe, axis: Axis, point: DesignPoint, gains: Mapping[str, float], *,
             settings: DKSettings = DKSettings(), spec: RobustSpec = _SPEC) -> DKPoint:
    """D-K iteration of one axis-point from ``gains`` (module docstring).

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The attitude axis.
    point : DesignPoint
        The design point (airspeeds in m/s).
    gains : mapping of str to float
        Starting P-PID gains (:data:`~vtolftc.synthesis.loops.PARAM_NAMES`), stabilising.
    settings : DKSettings, optional
        Iteration settings.
    spec : RobustSpec, optional
        The robust design's settings (weights, delays).

    Returns
    -------
    DKPoint
        Before/after and the history.

    Raises
    ------
    ValueError
        The starting gains do not stabilise the design plant.
    """
    w = robust_weights(af, axis, point, spec)
    G = w.plant(af)
    rp = cascade_rp(G, w.Ws, w.Wt, w.Wr)
    reqs: list[Any] = [CascadeChannel(G, Wt=delay_weight(spec.delays.extra_margin_s))]
    if w.Wd > 0:
        reqs.append(CascadeChannel(G, Wd=disturbance_weight(w)))
    params, _ = robust_parameters(af, axis, w.Wr.u_max_N_m, spec)
    theta0 = np.array([gains[k] for k in PARAM_NAMES], float)
    res = dk_iterate(rp, params, theta0, requirements=reqs if settings.keep_requirements else (),
                     order=settings.order,
                     max_iter=settings.max_iter, rel_tol=settings.rel_tol,
                     tune_iter=settings.tune_iter)
    th0 = res.steps[0].theta
    return DKPoint(axis, point.number, point.airspeed_m_s, _measure(af, w, reqs, th0),
                   _measure(af, w, reqs, res.theta),
                   dict(zip(PARAM_NAMES, (float(x) for x in th0), strict=True)),
                   dict(zip(PARAM_NAMES, (float(x) for x in res.theta), strict=True)), res)


def _job(args: tuple[Any, ...]) -> DKPoint:
    af, axis, point, gains, settings, spec = args
    return dk_point(af, axis, point, gains, settings=settings, spec=spec)


def dk_schedule(af: Airframe, points: Sequence[DesignPoint],
                gains: Mapping[str, Sequence[Mapping[str, float]]], *,
                axes: Sequence[Axis] = ("roll", "pitch", "yaw"),
                only: Callable[[Axis, DesignPoint], bool] | None = None,
                settings: DKSettings = DKSettings(), spec: RobustSpec = _SPEC,
                executor: Executor | None = None,
                progress: Callable[[str], None] | None = None) -> list[DKPoint]:
    """:func:`dk_point` at every axis-point of a gain schedule.

    Parameters
    ----------
    af : Airframe
        The airframe.
    points : sequence of DesignPoint
        The schedule's design points, in breakpoint order.
    gains : mapping of str to sequence of mapping
        ``gains[axis][i]``: the gains at ``points[i]``.
    axes : sequence of str, optional
        The axes to iterate.
    only : callable, optional
        ``only(axis, point)``: iterate this axis-point (others are skipped).
    settings : DKSettings, optional
        Iteration settings.
    spec : RobustSpec, optional
        The robust design's settings.
    executor : concurrent.futures.Executor, optional
        Runs the axis-points (default: this process, in order).
    progress : callable, optional
        ``progress(label)`` after each axis-point.

    Returns
    -------
    list of DKPoint
        In axis, then point order.
    """
    jobs = [(af, ax, p, gains[ax][i], settings, spec) for ax in axes
            for i, p in enumerate(points) if only is None or only(ax, p)]
    out: list[DKPoint] = []
    it = (executor.map(_job, jobs) if executor is not None else map(_job, jobs))
    for r in it:
        out.append(r)
        if progress is not None:
            progress(f"{r.axis} point {r.point}")
    return out


def dk_gains(gains: Mapping[str, Sequence[Mapping[str, float]]], points: Sequence[DesignPoint],
             results: Sequence[DKPoint]) -> dict[str, list[dict[str, float]]]:
    """The schedule with the D-K gains in place of the iterated axis-points.

    Parameters
    ----------
    gains : mapping of str to sequence of mapping
        The starting schedule, ``gains[axis][i]`` at ``points[i]``.
    points : sequence of DesignPoint
        The design points.
    results : sequence of DKPoint
        The iterated axis-points.

    Returns
    -------
    dict of str to list of dict
        The new schedule (a copy).
    """
    out = {ax: [dict(g) for g in rows] for ax, rows in gains.items()}
    index = {p.number: i for i, p in enumerate(points)}
    for r in results:
        out[r.axis][index[r.point]] = dict(r.gains_after)
    return out


def fmt_ms(x: float) -> str:
    """A delay in whole milliseconds.

    Parameters
    ----------
    x : float
        Delay [s] (inf: no crossover).

    Returns
    -------
    str
        ``"69"`` for 0.069 s, ``"inf"`` for inf.
    """
    return "inf" if not math.isfinite(x) else f"{1e3 * x:.0f}"


def dk_table(results: Sequence[DKPoint]) -> str:
    """Table 3 before/after as markdown: mu_RS, mu_RP (upper; lower bound of the D-K
    gains), delay margin [ms], the rotor-out channel and the D-K iterations run.

    Parameters
    ----------
    results : sequence of DKPoint
        The iterated axis-points.

    Returns
    -------
    str
        The markdown table (header included).
    """
    rows = ["| axis | No. | V [m/s] | mu_RS before | mu_RS D-K | mu_RP before | mu_RP D-K | "
            "mu_RP D-K lower | peak at [rad/s] | delay margin before / D-K [ms] | "
            "Wd*Sd before / D-K | K steps |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        b, a = r.before, r.after
        rows.append(
            f"| {r.axis} | {r.point} | {r.airspeed_m_s:g} | {b['mu_rs']:.3f} | "
            f"{a['mu_rs']:.3f} | {b['mu_rp']:.3f} | {a['mu_rp']:.3f} | {a['mu_rp_lower']:.3f} | "
            f"{a['mu_rp_peak_frequency_rad_s']:.3g} | {fmt_ms(b['delay_margin_s'])} / "
            f"{fmt_ms(a['delay_margin_s'])} | {b['Wd*Sd']:.3f} / {a['Wd*Sd']:.3f} | "
            f"{len(r.dk.steps) - 1} |")
    return "\n".join(rows) + "\n"
