"""Simple aircraft geometry for the viewers (rerun and viser), derived from the airframe.

Everything is in the body frame FRD (metres, origin at the centre of gravity): a fuselage, the
wing, one boom per lateral rotor station, the tail surfaces, one disc per lift rotor and one per
pusher. The shapes are for display only: sizes not in the airframe file (fuselage width, boom
thickness, propeller radius) are chosen to look right, not to be exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vtolftc.airframe.loader import Airframe

__all__ = ["Box", "Disc", "aircraft_geometry", "rotor_grid"]


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in body FRD: ``center_m`` and full ``size_m`` (x, y, z)."""

    name: str
    center_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    color: tuple[int, int, int]


@dataclass(frozen=True)
class Disc:
    """A propeller disc: ``center_m`` in body FRD, ``axis`` its unit thrust axis, ``radius_m``."""

    name: str                       # actuator name, e.g. "rotor_2b", "pusher_left"
    center_m: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius_m: float


def _t(v: np.ndarray | list[float]) -> tuple[float, float, float]:
    a = np.asarray(v, dtype=float)
    return (float(a[0]), float(a[1]), float(a[2]))


def aircraft_geometry(af: Airframe) -> tuple[list[Box], list[Disc]]:
    """Boxes (fuselage, wing, booms, tail) and discs (rotors, pushers) of ``af`` in body FRD."""
    lift = af.lift_rotors
    xs = np.array([r.position_m[0] for r in lift])
    ys = np.array([r.position_m[1] for r in lift])
    z_rot = float(np.mean([r.position_m[2] for r in lift]))
    stations = np.unique(np.round(ys, 3))
    spacing = np.min(np.diff(np.sort(stations))) if stations.size > 1 else 0.6
    pair_dx = float(np.min(np.abs(np.diff(np.unique(np.round(xs, 3)))))) if np.unique(
        np.round(xs, 3)).size > 1 else 1.0
    radius = float(min(0.45 * spacing, 0.45 * pair_dx, 0.35))
    nose = float(xs.max()) + 0.35
    tail = float(xs.min()) - 0.75
    span = af.wing.span_m
    chord = af.wing.chord_m
    boxes = [
        Box("fuselage", ((nose + tail) / 2, 0.0, 0.0), (nose - tail, 0.16, 0.16), (200, 200, 210)),
        Box("wing", (0.0, 0.0, -0.06), (chord, span, 0.03), (90, 140, 220)),
        Box("tailplane", (tail + 0.1, 0.0, -0.05), (0.18, 0.9, 0.02), (90, 140, 220)),
        Box("fin", (tail + 0.1, 0.0, -0.2), (0.18, 0.02, 0.3), (90, 140, 220)),
    ]
    for y in stations:
        if abs(y) < 0.05:
            continue
        x0, x1 = float(xs.max()) + 0.05, float(xs.min()) - 0.05
        boxes.append(Box(f"boom_{y:+.2f}", ((x0 + x1) / 2, float(y), z_rot + 0.04),
                         (x0 - x1, 0.04, 0.04), (60, 60, 60)))
    discs = [Disc(f"rotor_{r.name}", _t(r.position_m), _t(r.thrust_axis), radius) for r in lift]
    discs += [Disc(f"pusher_{p.name}", _t(p.position_m), _t(p.thrust_axis), 0.8 * radius)
              for p in af.pushers]
    return boxes, discs


def rotor_grid(af: Airframe) -> list[list[str | None]]:
    """The lift rotors' actuator names laid out as seen from above, nose up.

    Rows go from the front (largest x) to the rear, columns from left (most negative y) to
    right; a cell without a rotor is None. For DS-1: ``[[1a, 2a, 3a, 4a], [1b, 2b, 3b, 4b]]``
    (as ``rotor_*`` names).
    """
    lift = af.lift_rotors
    xs = sorted({round(float(r.position_m[0]), 3) for r in lift}, reverse=True)
    ys = sorted({round(float(r.position_m[1]), 3) for r in lift})
    grid: list[list[str | None]] = [[None] * len(ys) for _ in xs]
    for r in lift:
        i = xs.index(round(float(r.position_m[0]), 3))
        j = ys.index(round(float(r.position_m[1]), 3))
        grid[i][j] = f"rotor_{r.name}"
    return grid
