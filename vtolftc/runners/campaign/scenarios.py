"""Expansion of a :class:`~vtolftc.runners.campaign.spec.Spec` into its scenarios.

The order is fixed by the spec (fault families and their sets in file order, then phases,
winds, perturbations, seeds and controllers, the innermost last: the controllers of one flight
condition are neighbours, so a campaign stopped half-way has compared them on the same
scenarios), so a spec always expands to the same list; ``index`` is the position in it and
``scenario_id`` a short hash of everything that defines the flight (stable across machines
and Python versions).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import shlex
from dataclasses import dataclass
from typing import Any

from vtolftc.runners.campaign.spec import FaultSet, PerturbationSpec, Spec, SpecError, WindSpec

__all__ = ["CampaignScenario", "expand", "flight_order"]


@dataclass(frozen=True)
class CampaignScenario:
    """One scenario of a campaign: everything needed to fly it, picklable."""

    index: int
    scenario_id: str
    controller: str
    family: str
    fault_set: FaultSet
    phase: str
    fault_time_s: float
    wind: WindSpec
    perturbation: PerturbationSpec
    seed: int
    noise_level: str
    duration_s: float
    airframe_path: str | None
    gains_dir: str | None

    @property
    def faults_label(self) -> str:
        """The fault set's label (``--fault`` syntax, without the time)."""
        return self.fault_set.label

    @property
    def window_start_s(self) -> float:
        """Metrics window: from the injection (or the transition command, if earlier)."""
        return min(self.fault_time_s, 20.0)

    def fault_args(self) -> list[str]:
        """The faults in ``vtolftc fly --fault`` syntax, with the injection time."""
        out = []
        for a, kind, loss in self.fault_set.faults:
            what = f"loss={loss:g}" if kind == "loss" else kind
            out.append(f"{a}:{what}@{self.fault_time_s:g}")
        return out

    def gusts(self) -> list[tuple[float, float, tuple[float, float, float]]]:
        """(start s, duration s, amplitude NED m/s) of each gust, resolved to absolute time."""
        return [(g.start(self.fault_time_s), g.duration_s, g.amplitude_ned_m_s)
                for g in self.wind.gusts]

    def fly_command(self, out_dir: str = "runs/campaign") -> str:
        """The one ``vtolftc fly`` command that re-flies this scenario (plots, rerun file)."""
        args = ["vtolftc", "fly", "--case", "0", "--controller", self.controller,
                "--duration", f"{self.duration_s:g}"]
        for f in self.fault_args():
            args += ["--fault", f]
        if self.window_start_s != 20.0:
            args += ["--window-start", f"{self.window_start_s:g}"]
        w = self.wind
        if w.steady_ned_m_s != (0.0, 0.0, 0.0):
            args += ["--wind", ",".join(f"{v:g}" for v in w.steady_ned_m_s)]
        for start, dur, amp in self.gusts():
            args += ["--gust", ",".join(f"{v:g}" for v in (start, dur, *amp))]
        p = self.perturbation
        if p.mass_scale != 1.0:
            args += ["--mass-scale", f"{p.mass_scale:g}"]
        if p.inertia_scale != (1.0, 1.0, 1.0):
            args += ["--inertia-scale", ",".join(f"{v:g}" for v in p.inertia_scale)]
        if p.cg_offset_m != (0.0, 0.0, 0.0):
            args += ["--cg-offset", ",".join(f"{v:g}" for v in p.cg_offset_m)]
        if self.noise_level != "none":
            args += ["--noise", self.noise_level, "--noise-seed", str(self.seed)]
        if self.airframe_path:
            args += ["--airframe", self.airframe_path]
        if self.gains_dir:
            args += ["--gains", self.gains_dir]
        args += ["--out", f"{out_dir}/{self.scenario_id}"]
        return shlex.join(args)

    def key(self) -> dict[str, Any]:
        """What defines the flight (hashed into ``scenario_id``)."""
        return {
            "controller": self.controller, "faults": self.fault_args(),
            "duration_s": self.duration_s, "window_start_s": self.window_start_s,
            "wind": [list(self.wind.steady_ned_m_s),
                     [[s, d, list(a)] for s, d, a in self.gusts()]],
            "perturbation": [self.perturbation.mass_scale, list(self.perturbation.inertia_scale),
                             list(self.perturbation.cg_offset_m)],
            "noise": [self.noise_level, self.seed],
            "airframe": self.airframe_path, "gains": self.gains_dir,
        }


def _excluded(rules: tuple[dict[str, tuple[Any, ...]], ...], values: dict[str, Any]) -> bool:
    return any(all(values[k] in v for k, v in rule.items()) for rule in rules)


def expand(spec: Spec) -> list[CampaignScenario]:
    """Every scenario of ``spec`` in its fixed order; raises :class:`SpecError` when the
    product (after the ``[[exclude]]`` filters) is empty."""
    out: list[CampaignScenario] = []
    seen: set[str] = set()
    sets = [(fam.name, fs) for fam in spec.families for fs in fam.sets]
    for (fam, fs), (ph, t), wind, pert, seed, ctl in itertools.product(
            sets, spec.phases, spec.winds, spec.perturbations, spec.seeds, spec.controllers):
        values = {"controller": ctl, "family": fam, "phase": ph, "wind": wind.name,
                  "perturbation": pert.name, "seed": seed}
        if _excluded(spec.excludes, values):
            continue
        sc = CampaignScenario(
            index=len(out), scenario_id="", controller=ctl, family=fam, fault_set=fs,
            phase=ph, fault_time_s=t, wind=wind, perturbation=pert, seed=seed,
            noise_level=spec.noise_level, duration_s=spec.duration_s,
            airframe_path=spec.airframe_path, gains_dir=spec.gains_dir)
        digest = hashlib.sha256(json.dumps(sc.key(), sort_keys=True).encode()).hexdigest()[:12]
        if digest in seen:  # the same flight twice (e.g. two families listing one set)
            continue
        seen.add(digest)
        out.append(CampaignScenario(**{**sc.__dict__, "scenario_id": digest}))
    if not out:
        raise SpecError(f"{spec.source}: the product of the axes is empty (0 scenarios after "
                        "[[exclude]]): expected at least one controller x fault set x phase "
                        "x wind x perturbation x seed")
    return out


def flight_order(scenarios: list[CampaignScenario], n_controllers: int) -> list[CampaignScenario]:
    """The order scenarios are flown in: flight conditions (the ``n_controllers`` neighbours
    of the expansion) in a fixed pseudo-random order, each condition's controllers together.

    A campaign stopped half-way has then sampled every family, phase and wind evenly (and
    compared the controllers on the same conditions); results are stored by ``index``
    whatever the order, so the order never changes the result file.
    """
    def key(sc: CampaignScenario) -> tuple[str, int]:
        group = sc.index // max(1, n_controllers)
        return hashlib.sha256(f"order-{group}".encode()).hexdigest(), sc.index

    return sorted(scenarios, key=key)
