"""Wind acting on the simulated vehicle: a steady wind plus discrete "1 - cosine" gusts.

The wind is the velocity of the air mass in NED (m/s); the dynamics use the air-relative
velocity ``v - wind``. A :class:`Gust` is the discrete gust of the airworthiness standards
(e.g. MIL-F-8785C, CS-25.341): starting at ``start_s`` it rises as
``0.5 * amplitude * (1 - cos(2 pi (t - start) / duration))`` and is back to zero after
``duration_s``. Gusts add to each other and to the steady wind. Everything is a function of
simulated time only, so runs stay deterministic.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Gust", "WindField"]


def _vec3(v: Sequence[float], what: str) -> tuple[float, float, float]:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{what} = {v!r}: expected three finite numbers (NED, m/s)")
    return float(a[0]), float(a[1]), float(a[2])


@dataclass(frozen=True)
class Gust:
    """One 1 - cosine gust: peak ``amplitude_ned_m_s`` (NED, m/s) at ``start_s + duration_s/2``."""

    start_s: float
    duration_s: float
    amplitude_ned_m_s: tuple[float, float, float]

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start_s) and self.start_s >= 0.0):
            raise ValueError(f"gust start_s = {self.start_s!r}: expected a time >= 0 s")
        if not (math.isfinite(self.duration_s) and self.duration_s > 0.0):
            raise ValueError(f"gust duration_s = {self.duration_s!r}: expected a positive time")
        object.__setattr__(self, "amplitude_ned_m_s",
                           _vec3(self.amplitude_ned_m_s, "gust amplitude_ned_m_s"))

    def factor(self, t_s: float) -> float:
        """Shape of the gust at ``t_s``: 0 outside, 1 at its peak."""
        tau = (t_s - self.start_s) / self.duration_s
        if tau <= 0.0 or tau >= 1.0:
            return 0.0
        return 0.5 * (1.0 - math.cos(2.0 * math.pi * tau))


@dataclass(frozen=True)
class WindField:
    """Steady wind ``steady_ned_m_s`` (NED, m/s) plus ``gusts``."""

    steady_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gusts: tuple[Gust, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "steady_ned_m_s",
                           _vec3(self.steady_ned_m_s, "steady_ned_m_s"))
        object.__setattr__(self, "gusts", tuple(self.gusts))

    def at(self, t_s: float, out: np.ndarray) -> None:
        """Write the wind at simulated time ``t_s`` (NED, m/s) into ``out`` (3,)."""
        w0, w1, w2 = self.steady_ned_m_s
        for g in self.gusts:
            f = g.factor(t_s)
            if f != 0.0:
                a = g.amplitude_ned_m_s
                w0 += f * a[0]
                w1 += f * a[1]
                w2 += f * a[2]
        out[0] = w0
        out[1] = w1
        out[2] = w2
