"""What a synthesis run produced, in memory: the one type the pipeline, the export and the
report share (kept apart so that none of them imports another in a circle)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vtolftc.airframe.loader import Airframe
from vtolftc.synthesis.baselines import LqrAxis
from vtolftc.synthesis.design import AxisDesign
from vtolftc.synthesis.models import AXES, Axis
from vtolftc.synthesis.robustness import AxisRobustness
from vtolftc.synthesis.uncertainty import DesignPoint

__all__ = ["SynthesisResult"]


@dataclass
class SynthesisResult:
    """Everything the synthesis produced (in memory), plus per-stage wall times [s].

    Parameters
    ----------
    airframe : Airframe
        The airframe designed for.
    points : tuple of DesignPoint
        The design points.
    gs : dict of str to list of AxisDesign
        GS-SHIF designs per axis, one per point.
    shif : dict of str to AxisDesign
        The constant SHIF design per axis.
    lqr : dict of str to LqrAxis
        The LQR baseline per axis.
    mu_gs, mu_shif : dict of str to list of AxisRobustness
        mu analyses of the GS-SHIF and SHIF loops per axis and point.
    times : dict of str to float
        Wall time of each stage (s).
    files : dict of str to Path
        Files written, by role.
    settings : dict
        The settings the synthesis ran with.
    method : str
        ``"paper"`` or ``"robust"``.
    margins_gs, margins_shif : dict of str to list
        Loop margins of the GS-SHIF and SHIF designs per axis and point.
    """

    airframe: Airframe
    points: tuple[DesignPoint, ...]
    gs: dict[Axis, list[AxisDesign]]
    shif: dict[Axis, AxisDesign]
    lqr: dict[Axis, LqrAxis]
    mu_gs: dict[Axis, list[AxisRobustness]] = field(default_factory=dict)
    mu_shif: dict[Axis, list[AxisRobustness]] = field(default_factory=dict)
    times: dict[str, float] = field(default_factory=dict)
    files: dict[str, Path] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    method: str = "paper"
    #: robust method: loop margins (``LoopMargins``) per axis and point, GS-SHIF and SHIF
    margins_gs: dict[Axis, list[Any]] = field(default_factory=dict)
    margins_shif: dict[Axis, list[Any]] = field(default_factory=dict)

    def nominal_stable(self) -> dict[Axis, list[bool]]:
        """Per axis, whether each scheduled design point's nominal closed loop is stable.

        Returns
        -------
        dict of str to list of bool
            One verdict per design point.
        """
        return {ax: [d.stable for d in self.gs[ax]] for ax in AXES}
