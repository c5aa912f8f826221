"""Resident memory of a campaign's processes against the number of scenarios flown.

A campaign must not grow with its length: issue 24 asks that a 2000-scenario campaign grow
the parent's and each worker's resident set by < 50 MB. :class:`RssWatch` samples the
resident set size (``VmRSS`` of ``/proc/PID/status``, Linux) of the parent and of each of its
child processes (the pool's workers, by pid) each time a row arrives, i.e. against the
scenario count, never against the wall clock (or, with ``pids``, of given processes: a
Dask cluster's scheduler, nannies and workers, by pid, which need not descend from the
client; :func:`vtolftc.runners.campaign.dask_run.cluster_pids` finds them);
:func:`robust_slope` (Theil-Sen: the median of the pairwise slopes, which a few jumps of the
allocator's arenas do not move) gives the growth per scenario, and :meth:`RssWatch.growth`
its extrapolation to a campaign length.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["RssWatch", "child_pids", "robust_slope", "rss_bytes"]


def rss_bytes(pid: int) -> int | None:
    """Resident set size of process ``pid`` (bytes), None when it is gone or unreadable."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def child_pids(pid: int | None = None) -> list[int]:
    """The live descendants of ``pid`` (default: this process), by a scan of ``/proc``: the
    pool's workers whether forked from it or from its forkserver."""
    root = os.getpid() if pid is None else int(pid)
    parent: dict[int, int] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat", encoding="ascii", errors="replace") as fh:
                rest = fh.read().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if len(rest) > 1 and rest[0] != "Z":
            parent[int(d)] = int(rest[1])
    out: set[int] = set()
    frontier = {root}
    while frontier:
        frontier = {c for c, p in parent.items() if p in frontier} - out
        out |= frontier
    return sorted(out)


def robust_slope(x: Sequence[float], y: Sequence[float], max_points: int = 400) -> float:
    """Theil-Sen slope of ``y`` against ``x``: the median of the slopes between every pair of
    points with distinct ``x`` (evenly thinned to ``max_points`` points first). NaN with fewer
    than two distinct ``x``."""
    xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if xa.size > max_points:
        idx = np.linspace(0, xa.size - 1, max_points).round().astype(int)
        xa, ya = xa[idx], ya[idx]
    i, j = np.triu_indices(xa.size, k=1)
    dx = xa[j] - xa[i]
    ok = dx != 0
    if not ok.any():
        return float("nan")
    return float(np.median((ya[j] - ya[i])[ok] / dx[ok]))


@dataclass
class RssWatch:
    """RSS samples (scenario count, bytes) of the parent and of each descendant by pid.

    Call :meth:`sample` with the number of scenarios finished so far (e.g. after each row);
    children are looked up on every sample, so workers that start late are caught.
    ``labels`` names processes (pid -> e.g. ``"dask worker"``) for :meth:`label`."""

    parent: int = field(default_factory=os.getpid)
    samples: dict[int, list[tuple[int, int]]] = field(default_factory=dict)
    labels: dict[int, str] = field(default_factory=dict)

    def sample(self, n_done: int, pids: Iterable[int] | None = None) -> None:
        """Record the RSS of the parent and its live children at ``n_done`` scenarios, or
        with ``pids``, of the parent and those processes (no scan of ``/proc``)."""
        others = child_pids(self.parent) if pids is None else pids
        for pid in dict.fromkeys((self.parent, *others)):
            rss = rss_bytes(pid)
            if rss is not None:
                self.samples.setdefault(pid, []).append((int(n_done), rss))

    def label(self, pid: int) -> str:
        """Its name in ``labels``, else ``parent`` or ``worker PID``."""
        if pid in self.labels:
            return f"{self.labels[pid]} {pid}"
        return "parent" if pid == self.parent else f"worker {pid}"

    def growth(self, scenarios: int, skip: float = 0.25) -> dict[int, dict[str, float]]:
        """Per process: its robust slope (bytes per scenario) over the samples after the first
        ``skip`` fraction of the scenarios (the warm-up), that slope times ``scenarios``
        (bytes), the RSS at the first and last sample (bytes) and the number of samples used.
        Processes with fewer than 5 samples after the warm-up are left out."""
        if not self.samples:
            return {}
        last = max(n for s in self.samples.values() for n, _ in s)
        start = skip * last
        out: dict[int, dict[str, float]] = {}
        for pid, s in self.samples.items():
            used = [(n, r) for n, r in s if n >= start]
            if len(used) < 5:
                continue
            n, r = zip(*used, strict=True)
            slope = robust_slope(n, r)
            out[pid] = {"slope_b_per_scenario": slope, "growth_b": slope * scenarios,
                        "rss_first_b": float(s[0][1]), "rss_last_b": float(s[-1][1]),
                        "samples": float(len(used))}
        return out
