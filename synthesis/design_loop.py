"""The one design loop of the attitude synthesis: design points x axes x starts, pick, designs.

Both methods (the paper's, :mod:`vtolftc.synthesis.design`, and the robust one,
:mod:`vtolftc.synthesis.robust`) run :func:`run_design_loop`; they differ only in their
:class:`DesignMethod`: the weights of an (axis, point), the tuning problem over a list of
weights, and the design made of a finished tune. The loop owns everything else: the seeds,
the order, the cutting of the work for an executor, the tie-break among starts.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, as_completed
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.hinfnorm import hinf_norm
from vtolftc.synthesis.loops import PARAM_NAMES, CascadeChannel
from vtolftc.synthesis.models import AXES, Axis
from vtolftc.synthesis.structured import (
    StartRecord,
    TuneResult,
    TuningProblem,
    collect_starts,
    run_start,
    start_jobs,
    tune,
)
from vtolftc.synthesis.uncertainty import DesignPoint

__all__ = [
    "SHIF_TAG",
    "AxisDesign",
    "DesignMethod",
    "TuningSetup",
    "achieved_norms",
    "pick_start",
    "point_seed",
    "run_design_loop",
    "tune_axis",
]

#: The seed tag of a SHIF tune (GS-SHIF tunes use their point number).
SHIF_TAG = 100


@dataclass
class AxisDesign:
    """Result of one tune: gains, per-requirement norms, closed-loop poles, weights used.

    ``norms`` keys: ``gamma`` (the stacked norm of eq. 8, max over models for SHIF),
    ``Ws*S``, ``Wt*T``, ``Wr*R`` (each requirement alone; for SHIF the max over models).
    ``bounds``: where each gain bound comes from (robust method), or None.
    """

    axis: Axis
    label: str                      # "point 3" or "all points"
    gains: dict[str, float]
    norms: dict[str, float]
    stable: bool
    poles: list[list[complex]]      # closed-loop poles per model
    weights: list[Any]
    starts: int
    message: str = ""
    per_model_norms: list[dict[str, float]] = field(default_factory=list)
    bounds: dict[str, dict[str, Any]] | None = None

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
    """||Ws S||_inf: the tie-break among equally good starts (:func:`pick_start`)."""
    A, B, C, D = ch(theta)
    keep = [i for i, n in enumerate(ch.outputs) if n == "Ws*S"]
    return hinf_norm((A, B, C[keep], D[keep])).value if keep else 0.0


def pick_start(res: TuneResult, channels: Sequence[CascadeChannel]) -> NDArray[np.float64]:
    """Tie-break among near-optimal starts: among the starts whose objective is within 0.1 %
    of the best, the one with the smallest ||Ws S||_inf over ``channels`` (the reasons are in
    :mod:`vtolftc.synthesis.design`'s docstring)."""
    if not res.stable:
        return res.theta
    best = res.value
    cands = [r for r in res.starts if math.isfinite(r.value) and r.value <= best * (1 + 1e-3)]
    scored = [(max(_secondary(c, r.theta) for c in channels), r.index, r.theta) for r in cands]
    scored.sort(key=lambda t: (t[0], t[1]))
    return np.asarray(scored[0][2], float)


def point_seed(seed: int, axis: Axis, tag: int) -> int:
    """The random-start seed of one tune: independent streams per (seed, axis, point tag)."""
    return int(np.random.SeedSequence([seed, AXES.index(axis), tag]).generate_state(1)[0])


@dataclass
class TuningSetup:
    """A tuning problem and what its method needs to make a design of the result: the
    plants and channels per model, and method-specific ``extra`` data."""

    problem: TuningProblem
    plants: list[Any]
    chans: list[CascadeChannel]
    extra: Any = None


class DesignMethod(Protocol):
    """What a synthesis method gives the loop (must pickle, for worker processes)."""

    def weights(self, af: Airframe, axis: Axis, point: DesignPoint) -> Any:
        """The weights of ``axis`` at ``point``."""
        ...

    def setup(self, af: Airframe, axis: Axis, weights: list[Any]) -> TuningSetup:
        """The (multi-model) tuning problem of ``axis`` over the points of ``weights``."""
        ...

    def design(self, axis: Axis, weights: list[Any], label: str, n_starts: int,
               setup: TuningSetup, res: TuneResult) -> AxisDesign:
        """The design of a finished tune (tie-break, norms, poles)."""
        ...


def tune_axis(method: DesignMethod, af: Airframe, axis: Axis, weights: list[Any], label: str,
              n_starts: int, seed: int, max_iter: int) -> AxisDesign:
    """One tune of ``axis`` over the points of ``weights`` (one point: GS-SHIF; all: SHIF)."""
    st = method.setup(af, axis, weights)
    res = tune(st.problem, n_starts=n_starts, seed=seed, max_iter=max_iter)
    return method.design(axis, weights, label, n_starts, st, res)


def _label(number: int) -> str:
    return f"point {number}"


def _weights_job(args: tuple[Any, ...]) -> tuple[tuple[str, DesignPoint], Any]:
    method, af, axis, point = args
    return (axis, point), method.weights(af, axis, point)


def _gs_job(args: tuple[Any, ...]) -> tuple[tuple[str, int], AxisDesign]:
    method, af, axis, w, n_starts, seed, max_iter = args
    n = w.point.number
    return (axis, n), tune_axis(method, af, axis, [w], _label(n), n_starts,
                                point_seed(seed, axis, n), max_iter)


def _start_job(args: tuple[Any, ...]) -> tuple[tuple[str, int], StartRecord]:
    axis, job = args
    return (axis, int(job[1])), run_start(job)


def run_design_loop(method: DesignMethod, af: Airframe, points: Sequence[DesignPoint], *,
                    shif_points: Sequence[DesignPoint] | None = None, n_starts: int = 4,
                    seed: int = 0, executor: Executor | None = None, shif: bool = True,
                    progress: Callable[[str], None] | None = None, max_iter: int = 40,
                    on_design: Callable[[tuple[str, int], AxisDesign], None] | None = None,
                    ) -> tuple[dict[Axis, list[AxisDesign]], dict[Axis, AxisDesign]]:
    """All GS-SHIF tunes (axes x ``points``) and, with ``shif``, one SHIF tune per axis over
    ``shif_points`` (default ``points``), by ``method``.

    Deterministic: each tune's seed derives from (seed, axis, point number; SHIF
    :data:`SHIF_TAG`), whatever the execution order. Without ``executor`` the tunes run in
    this process, SHIF first. With one (e.g. a ``ProcessPoolExecutor``) the work is cut finer
    than one job per tune so that every worker stays busy to the end: first the weights of
    every (axis, point), each computed once; then every start of the SHIF tunes (the longest
    jobs, submitted first) and the GS-SHIF tunes. A SHIF tune's start records are combined in
    start order (:func:`vtolftc.synthesis.structured.collect_starts`): the same result, bit for
    bit, as the sequential run. ``progress(label)`` is called after each finished tune,
    ``on_design(key, design)`` with each finished design (key ``(axis, point number)``,
    ``(axis, 0)`` for SHIF), e.g. to queue its analysis behind the tunes still running.

    Returns
    -------
    gs : dict
        Axis -> the GS-SHIF designs in ``points`` order.
    shif : dict
        Axis -> the SHIF design (empty without ``shif``).
    """
    spts = tuple(points if shif_points is None else shif_points)
    results: dict[tuple[str, int], AxisDesign] = {}

    def done(key: tuple[str, int], d: AxisDesign) -> None:
        results[key] = d
        if on_design is not None:
            on_design(key, d)
        if progress is not None:
            progress(f"{key[0]} {'SHIF' if key[1] == 0 else _label(key[1])}")

    need = list(points) + [p for p in spts if shif and p not in points]
    if executor is None:
        weights = {(ax, p): method.weights(af, ax, p) for ax in AXES for p in need}
        if shif:  # the longest jobs first
            for ax in AXES:
                done((ax, 0), tune_axis(method, af, ax, [weights[(ax, p)] for p in spts],
                                        "all points", n_starts, point_seed(seed, ax, SHIF_TAG),
                                        max_iter))
        for ax in AXES:
            for p in points:
                done(*_gs_job((method, af, ax, weights[(ax, p)], n_starts, seed, max_iter)))
    else:
        wfuts = [executor.submit(_weights_job, (method, af, ax, p)) for ax in AXES for p in need]
        weights = dict(f.result() for f in wfuts)
        shif_setup: dict[Axis, tuple[list[Any], TuningSetup]] = {}
        records: dict[Axis, list[StartRecord]] = {ax: [] for ax in AXES}
        futs = []
        if shif:
            for ax in AXES:
                ws = [weights[(ax, p)] for p in spts]
                st = method.setup(af, ax, ws)
                shif_setup[ax] = (ws, st)
                for job in start_jobs(st.problem, n_starts=n_starts,
                                      seed=point_seed(seed, ax, SHIF_TAG), max_iter=max_iter):
                    futs.append(executor.submit(_start_job, (ax, job)))
        futs += [executor.submit(_gs_job, (method, af, ax, weights[(ax, p)], n_starts, seed,
                                           max_iter)) for ax in AXES for p in points]
        for f in as_completed(futs):
            key, r = f.result()
            if isinstance(r, AxisDesign):
                done(key, r)
                continue
            ax = key[0]
            records[ax].append(r)
            if len(records[ax]) == n_starts + 1:
                ws, st = shif_setup[ax]
                res = collect_starts(st.problem, records[ax])
                done((ax, 0), method.design(ax, ws, "all points", n_starts, st, res))
    gs = {ax: [results[(ax, p.number)] for p in points] for ax in AXES}
    sh = {ax: results[(ax, 0)] for ax in AXES} if shif else {}
    return gs, sh
