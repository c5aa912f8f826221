"""Campaign specification files (TOML): what is swept, validated like the airframe file.

A spec declares axes and their cartesian product, minus ``[[exclude]]`` filters::

    [campaign]
    name = "single-rotor"
    description = "..."
    duration_s = 60.0                       # simulated seconds per scenario, (0, 3600]
    controllers = ["gs-shif", "shif", "lqr"]
    phases = ["hover", "transition", "cruise"]   # or "transition+5", or a time in s
    # optional: airframe = "my.toml" (relative to the spec), gains = "dir/"

    [timing]                                # optional; defaults shown
    hover_s = 15.0                          # "hover": in hover, before the transition (20 s)
    transition_after_s = 3.0                # "transition": this long after its start
    cruise_s = 40.0                         # "cruise": wing-borne (transition ends ~28 s)

    [[faults]]                              # one table per fault family
    family = "rotor-off"
    generate = "each"                       # each | subsets | list
    actuators = ["lift_rotors"]             # names or groups (lift_rotors, pushers, ...)
    kinds = ["off"]                         # off | stuck | loss
    # magnitudes = [0.25, 0.5, 0.75]        # losses (fractions in (0, 1]) when kinds has loss
    # k = 2                                 # subsets: every k-subset of the actuators
    # sets = [["rotor_2b:loss=0.5", "ailerons:loss=0.2"]]   # list: explicit fault sets

    [[wind]]                                # optional axis; default one calm case
    name = "crosswind"
    steady_ned_m_s = [0.0, 5.0, 0.0]
    gusts = [{ after_fault_s = 2.0, duration_s = 2.0, amplitude_ned_m_s = [0.0, 4.0, 0.0] }]

    [[perturbation]]                        # optional axis; default the nominal airframe
    name = "heavy-aft"
    mass_scale = 1.1
    inertia_scale = 1.1                     # or [sx, sy, sz]
    cg_offset_m = [-0.02, 0.0, 0.0]

    [noise]                                 # optional: state-estimate noise and its seeds
    level = "typical"                       # none | typical
    seeds = [0, 1, 2]

    [[exclude]]                             # drop every scenario matching all given keys
    family = "pusher"
    phase = "hover"

    [[gate]]                                # CI gating: minimum survival fraction
    family = "rotor-off"                    # optional (default: every family)
    controller = "gs-shif"                  # optional (default: every controller)
    min_survival = 0.5

Every problem is one :class:`SpecError` line naming the field, the value found and what was
expected (the CLI prints it and exits with status 2).
"""

from __future__ import annotations

import hashlib
import itertools
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vtolftc.firmware_sim.vehicle.faults import (
    FaultError,
    FaultKind,
    expand_actuators,
    parse_fault_spec,
)

__all__ = [
    "CONTROLLERS",
    "FaultFamily",
    "FaultSet",
    "Gate",
    "GustSpec",
    "PerturbationSpec",
    "Spec",
    "SpecError",
    "WindSpec",
    "load_spec",
    "parse_spec",
]

CONTROLLERS = ("gs-shif", "shif", "lqr")
TRANSITION_S = 20.0  # the paper's timeline: front transition commanded at t = 20 s
MAX_WIND_M_S = 30.0
AXES = ("controller", "family", "phase", "wind", "perturbation", "seed")


class SpecError(ValueError):
    """A bad campaign spec: one line naming the field, the value and what was expected."""


@dataclass(frozen=True)
class FaultSet:
    """One set of simultaneous faults: ``(actuator, kind, loss)`` triples, a label in the
    ``--fault`` syntax (without the time) and the family it belongs to."""

    family: str
    label: str
    faults: tuple[tuple[str, str, float], ...]


@dataclass(frozen=True)
class FaultFamily:
    """A named group of fault sets (one ``[[faults]]`` entry of the spec), reported together."""
    name: str
    sets: tuple[FaultSet, ...]


@dataclass(frozen=True)
class GustSpec:
    """A 1 - cosine gust starting at ``start_s`` or ``after_fault_s`` after the injection."""

    duration_s: float
    amplitude_ned_m_s: tuple[float, float, float]
    start_s: float | None = None
    after_fault_s: float | None = None

    def start(self, fault_time_s: float) -> float:
        """Gust start (s, simulated): ``start_s``, else ``after_fault_s`` after ``fault_time_s``."""
        return self.start_s if self.start_s is not None else fault_time_s + float(
            self.after_fault_s or 0.0)


@dataclass(frozen=True)
class WindSpec:
    """A named wind condition: steady wind in NED (m/s) plus 1 - cosine gusts."""
    name: str
    steady_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gusts: tuple[GustSpec, ...] = ()

    @property
    def calm(self) -> bool:
        """True for no steady wind and no gusts."""
        return self.steady_ned_m_s == (0.0, 0.0, 0.0) and not self.gusts


@dataclass(frozen=True)
class PerturbationSpec:
    """A named airframe perturbation: mass and inertia scales, CG offset (body FRD, m)."""
    name: str
    mass_scale: float = 1.0
    inertia_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    cg_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def nominal(self) -> bool:
        """True when the perturbation changes nothing (scales 1, offset 0)."""
        return (self.mass_scale == 1.0 and self.inertia_scale == (1.0, 1.0, 1.0)
                and self.cg_offset_m == (0.0, 0.0, 0.0))


@dataclass(frozen=True)
class Gate:
    """CI gate: minimum survival fraction, optionally for one fault family and/or controller."""
    min_survival: float
    family: str | None = None
    controller: str | None = None


@dataclass(frozen=True)
class Spec:
    """A validated campaign spec (see the module docstring)."""

    source: str
    sha256: str
    name: str
    description: str
    duration_s: float
    controllers: tuple[str, ...]
    phases: tuple[tuple[str, float], ...]          # (name, injection time s)
    families: tuple[FaultFamily, ...]
    winds: tuple[WindSpec, ...]
    perturbations: tuple[PerturbationSpec, ...]
    noise_level: str
    seeds: tuple[int, ...]
    excludes: tuple[dict[str, tuple[Any, ...]], ...]
    gates: tuple[Gate, ...]
    airframe_path: str | None = None
    gains_dir: str | None = None
    text: str = field(default="", repr=False)


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------

_TOP = {"campaign", "timing", "faults", "wind", "perturbation", "noise", "exclude", "gate"}
_CAMPAIGN = {"name", "description", "duration_s", "controllers", "phases", "airframe", "gains"}
_TIMING = {"hover_s", "transition_after_s", "cruise_s"}
_FAULTS = {"family", "generate", "actuators", "kinds", "magnitudes", "k", "sets"}
_WIND = {"name", "steady_ned_m_s", "gusts"}
_GUST = {"start_s", "after_fault_s", "duration_s", "amplitude_ned_m_s"}
_PERT = {"name", "mass_scale", "inertia_scale", "cg_offset_m"}
_NOISE = {"level", "seeds"}
_GATE = {"family", "controller", "min_survival"}
_PHASE_RE = re.compile(r"^transition\s*\+\s*([0-9.]+)\s*s?$")


class _R:
    """Helpers that turn a problem into one SpecError line."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, value: Any, expected: str) -> SpecError:
        return SpecError(f"{self.source}: field '{where}' = {value!r}: expected {expected}")

    def keys(self, table: Any, allowed: set[str], where: str) -> Mapping[str, Any]:
        if not isinstance(table, dict):
            raise self.fail(where, table, "a table")
        for key in table:
            if key not in allowed:
                at = f"{where}.{key}" if where else key
                raise SpecError(f"{self.source}: unknown key '{at}': expected one of: "
                                f"{', '.join(sorted(allowed))}")
        return table

    def number(self, table: Mapping[str, Any], key: str, where: str, lo: float, hi: float,
               unit: str, default: float | None = None, open_lo: bool = False) -> float:
        if key not in table:
            if default is None:
                raise SpecError(f"{self.source}: missing field '{where}.{key}'")
            return default
        v = table[key]
        ok = (not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)
              and (lo < v if open_lo else lo <= v) and v <= hi)
        if not ok:
            rng = f"({lo:g}, {hi:g}]" if open_lo else f"[{lo:g}, {hi:g}]"
            raise self.fail(f"{where}.{key}", v, f"a number in {rng}{unit}")
        return float(v)

    def string(self, table: Mapping[str, Any], key: str, where: str,
               default: str | None = None) -> str:
        if key not in table:
            if default is None:
                raise SpecError(f"{self.source}: missing field '{where}.{key}'")
            return default
        v = table[key]
        if not isinstance(v, str) or not v.strip():
            raise self.fail(f"{where}.{key}", v, "a non-empty string")
        return v.strip()

    def str_list(self, table: Mapping[str, Any], key: str, where: str,
                 default: Sequence[str] | None = None) -> list[str]:
        if key not in table:
            if default is None:
                raise SpecError(f"{self.source}: missing field '{where}.{key}'")
            return list(default)
        v = table[key]
        if isinstance(v, str):
            v = [v]
        if not isinstance(v, list) or not v or not all(isinstance(x, str) and x for x in v):
            raise self.fail(f"{where}.{key}", v, "a non-empty list of strings")
        return list(v)

    def vec3(self, table: Mapping[str, Any], key: str, where: str, lo: float, hi: float,
             unit: str, default: tuple[float, float, float], scalar_ok: bool = False,
             ) -> tuple[float, float, float]:
        if key not in table:
            return default
        v = table[key]
        if scalar_ok and not isinstance(v, bool) and isinstance(v, int | float):
            v = [v, v, v]
        ok = (isinstance(v, list) and len(v) == 3 and all(
            not isinstance(x, bool) and isinstance(x, int | float) and math.isfinite(x)
            and lo <= x <= hi for x in v))
        if not ok:
            what = "a number or " if scalar_ok else ""
            raise self.fail(f"{where}.{key}", v,
                            f"{what}three numbers in [{lo:g}, {hi:g}]{unit}")
        return float(v[0]), float(v[1]), float(v[2])

    def tables(self, doc: Mapping[str, Any], key: str) -> list[Any]:
        v = doc.get(key, [])
        if not isinstance(v, list):
            raise self.fail(key, v, f"an array of tables ([[{key}]])")
        return v


def load_spec(path: str | Path, actuator_names: Sequence[str] | None = None) -> Spec:
    """Read and validate a spec file; raises :class:`SpecError` (one line) on any problem.

    ``actuator_names`` defaults to those of the spec's airframe (the shipped DS-1 unless the
    spec names one).
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise SpecError(f"{p}: cannot read the campaign spec ({exc.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise SpecError(f"{p}: not a UTF-8 text file") from None
    return parse_spec(text, source=str(p), base_dir=p.parent, actuator_names=actuator_names)


def parse_spec(text: str, *, source: str = "<spec>", base_dir: Path | None = None,
               actuator_names: Sequence[str] | None = None) -> Spec:
    """Validate the TOML text of a spec (see :func:`load_spec`)."""
    r = _R(source)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{source}: not valid TOML: {exc}") from None
    r.keys(doc, _TOP, "")
    if "campaign" not in doc:
        raise SpecError(f"{source}: missing table '[campaign]'")
    c = r.keys(doc["campaign"], _CAMPAIGN, "campaign")
    name = r.string(c, "name", "campaign")
    description = c.get("description", "")
    if not isinstance(description, str):
        raise r.fail("campaign.description", description, "a string")
    duration = r.number(c, "duration_s", "campaign", 0.0, 3600.0, " (s)", open_lo=True)
    controllers = _controllers(r, c)
    airframe_path, gains_dir = _paths(r, c, base_dir if base_dir is not None else Path("."))
    if actuator_names is None:
        from vtolftc.airframe.loader import AirframeError
        from vtolftc.firmware_sim.vehicle.flyable import load_flyable_airframe

        try:
            actuator_names = load_flyable_airframe(airframe_path).actuator_names
        except AirframeError as exc:
            raise SpecError(f"{source}: campaign.airframe: {exc}") from None

    phases = _phases(r, c, doc, duration)

    families = [_family(r, f, i, actuator_names) for i, f in enumerate(r.tables(doc, "faults"))]
    if not families:
        raise SpecError(f"{source}: no [[faults]] table: expected at least one fault family")
    names = [f.name for f in families]
    if len(set(names)) != len(names):
        raise r.fail("faults.family", names, "a distinct name for every family")

    winds = [_wind(r, w, i) for i, w in enumerate(r.tables(doc, "wind"))] or [
        WindSpec("calm")]
    perts = [_pert(r, p, i) for i, p in enumerate(r.tables(doc, "perturbation"))] or [
        PerturbationSpec("nominal")]
    for what, items in (("wind", winds), ("perturbation", perts)):
        nm = [x.name for x in items]
        if len(set(nm)) != len(nm):
            raise r.fail(f"{what}.name", nm, "a distinct name for every entry")

    level, seeds = _noise(r, doc)

    axis_values: dict[str, set[Any]] = {
        "controller": set(controllers), "family": set(names),
        "phase": {p for p, _ in phases}, "wind": {w.name for w in winds},
        "perturbation": {p.name for p in perts}, "seed": set(seeds)}
    excludes = _excludes(r, doc, axis_values)
    gates = _gates(r, doc, names, controllers)

    spec = Spec(
        source=source, sha256=hashlib.sha256(text.encode("utf-8")).hexdigest(), name=name,
        description=description, duration_s=duration, controllers=tuple(controllers),
        phases=tuple(phases), families=tuple(families), winds=tuple(winds),
        perturbations=tuple(perts), noise_level=level, seeds=tuple(seeds),
        excludes=tuple(excludes), gates=tuple(gates), airframe_path=airframe_path,
        gains_dir=gains_dir, text=text)
    return spec


def _controllers(r: _R, c: Mapping[str, Any]) -> list[str]:
    """``campaign.controllers``: known names, each once."""
    controllers = r.str_list(c, "controllers", "campaign", CONTROLLERS)
    for ctl in controllers:
        if ctl not in CONTROLLERS:
            raise r.fail("campaign.controllers", controllers,
                         f"controller names among {', '.join(CONTROLLERS)} (not {ctl!r})")
    if len(set(controllers)) != len(controllers):
        raise r.fail("campaign.controllers", controllers, "each controller once")
    return controllers


def _paths(r: _R, c: Mapping[str, Any], base: Path) -> tuple[str | None, str | None]:
    """``campaign.airframe`` (a file) and ``campaign.gains`` (a directory), resolved against
    ``base``; None where the spec names none."""
    airframe_path = gains_dir = None
    if "airframe" in c:
        airframe_path = str((base / r.string(c, "airframe", "campaign")).resolve())
        if not Path(airframe_path).is_file():
            raise r.fail("campaign.airframe", c["airframe"], "an airframe file (not found)")
    if "gains" in c:
        gains_dir = str((base / r.string(c, "gains", "campaign")).resolve())
        if not Path(gains_dir).is_dir():
            raise r.fail("campaign.gains", c["gains"],
                         "a directory holding gs-shif.json, shif.json and lqr.json")
    return airframe_path, gains_dir


def _phases(r: _R, c: Mapping[str, Any], doc: Mapping[str, Any],
            duration: float) -> list[tuple[str, float]]:
    """``campaign.phases`` with the ``[timing]`` table: (phase name, injection time [s])."""
    t = r.keys(doc.get("timing", {}), _TIMING, "timing")
    hover_s = r.number(t, "hover_s", "timing", 0.0, TRANSITION_S, " (s, before the "
                       "transition at 20 s)", default=15.0)
    trans_after = r.number(t, "transition_after_s", "timing", 0.0, 60.0, " (s)", default=3.0)
    cruise_s = r.number(t, "cruise_s", "timing", TRANSITION_S, 3600.0, " (s)", default=40.0)

    phase_names = c.get("phases", ["hover", "transition", "cruise"])
    if not isinstance(phase_names, list) or not phase_names:
        raise r.fail("campaign.phases", phase_names, "a non-empty list of phases (hover, "
                     "transition, transition+SECONDS, cruise) or times in s")
    phases: list[tuple[str, float]] = []
    for ph in phase_names:
        at: float
        raw = ph
        if isinstance(ph, bool):
            at = -1.0
        elif isinstance(ph, int | float):
            at, ph = float(ph), f"t={float(ph):g}"
        elif ph == "hover":
            at = hover_s
        elif ph == "transition":
            at = TRANSITION_S + trans_after
        elif ph == "cruise":
            at = cruise_s
        elif isinstance(ph, str) and (m := _PHASE_RE.match(ph)):
            at = TRANSITION_S + float(m.group(1))
        else:
            raise r.fail("campaign.phases", ph, "hover, transition, transition+SECONDS, "
                         "cruise or an injection time in s")
        if not (math.isfinite(at) and 0.0 <= at < duration):
            raise r.fail("campaign.phases", raw, f"an injection time in [0, {duration:g}) s "
                         "(within campaign.duration_s)")
        if any(n == ph for n, _ in phases):
            raise r.fail("campaign.phases", raw, "each phase once")
        phases.append((str(ph), at))
    return phases


def _noise(r: _R, doc: Mapping[str, Any]) -> tuple[str, list[int]]:
    """The ``[noise]`` table: (level, seeds)."""
    n = r.keys(doc.get("noise", {}), _NOISE, "noise")
    level = n.get("level", "none")
    if level not in ("none", "typical"):
        raise r.fail("noise.level", level, "none or typical")
    seeds = n.get("seeds", [0])
    if (not isinstance(seeds, list) or not seeds or not all(
            isinstance(s, int) and not isinstance(s, bool) and 0 <= s < 2**32 for s in seeds)
            or len(set(seeds)) != len(seeds)):
        raise r.fail("noise.seeds", seeds, "a non-empty list of distinct integers in "
                     "[0, 2^32)")
    if level == "none" and len(seeds) > 1:
        raise r.fail("noise.seeds", seeds, "one seed when noise.level = 'none' (without "
                     "noise every seed flies the same scenario)")
    return level, seeds


def _excludes(r: _R, doc: Mapping[str, Any],
              axis_values: Mapping[str, set[Any]]) -> list[dict[str, tuple[Any, ...]]]:
    """The ``[[exclude]]`` rules, each value among ``axis_values`` of its axis."""
    excludes = []
    for i, ex in enumerate(r.tables(doc, "exclude")):
        where = f"exclude[{i}]"
        r.keys(ex, set(AXES), where)
        if not ex:
            raise r.fail(where, ex, f"at least one of {', '.join(AXES)}")
        rule: dict[str, tuple[Any, ...]] = {}
        for k, v in ex.items():
            vals = tuple(v) if isinstance(v, list) else (v,)
            for x in vals:
                if x not in axis_values[k]:
                    raise r.fail(f"{where}.{k}", x, f"one of {sorted(map(str, axis_values[k]))}")
            rule[k] = vals
        excludes.append(rule)
    return excludes


def _gates(r: _R, doc: Mapping[str, Any], names: Sequence[str],
           controllers: Sequence[str]) -> list[Gate]:
    """The ``[[gate]]`` tables (family among ``names``, controller among ``controllers``)."""
    gates = []
    for i, g in enumerate(r.tables(doc, "gate")):
        where = f"gate[{i}]"
        r.keys(g, _GATE, where)
        ms = r.number(g, "min_survival", where, 0.0, 1.0, " (fraction survived)")
        fam = g.get("family")
        if fam is not None and fam not in names:
            raise r.fail(f"{where}.family", fam, f"one of the families {', '.join(names)}")
        ctl = g.get("controller")
        if ctl is not None and ctl not in controllers:
            raise r.fail(f"{where}.controller", ctl,
                         f"one of the campaign's controllers {', '.join(controllers)}")
        gates.append(Gate(ms, fam, ctl))
    return gates


def _family(r: _R, f: Any, i: int, actuator_names: Sequence[str]) -> FaultFamily:
    where = f"faults[{i}]"
    r.keys(f, _FAULTS, where)
    fam = r.string(f, "family", where)
    gen = f.get("generate", "each")
    if gen not in ("each", "subsets", "list"):
        raise r.fail(f"{where}.generate", gen, "each, subsets or list")
    allowed = {"each": {"family", "generate", "actuators", "kinds", "magnitudes"},
               "subsets": {"family", "generate", "actuators", "kinds", "magnitudes", "k"},
               "list": {"family", "generate", "sets"}}[gen]
    for key in f:
        if key not in allowed:
            raise SpecError(f"{r.source}: unknown key '{where}.{key}' for generate = "
                            f"{gen!r}: expected one of: {', '.join(sorted(allowed))}")
    if gen == "list":
        return FaultFamily(fam, _listed_sets(r, f, where, fam, actuator_names))

    acts_raw = r.str_list(f, "actuators", where)
    try:
        acts = expand_actuators(acts_raw, actuator_names)
    except FaultError as exc:
        raise SpecError(f"{r.source}: field '{where}.actuators' = {acts_raw!r}: {exc}") from None
    if len(set(acts)) != len(acts):
        raise r.fail(f"{where}.actuators", acts_raw, "each actuator once")
    kinds = r.str_list(f, "kinds", where)
    for k in kinds:
        if k not in {x.value for x in FaultKind}:
            raise r.fail(f"{where}.kinds", kinds, f"kinds among off, stuck, loss (not {k!r})")
    mags = _magnitudes(r, f, where, kinds)
    variants: list[tuple[str, float]] = []
    for k in kinds:
        if k == "loss":
            variants += [("loss", m) for m in mags]
        else:
            variants.append((k, 1.0 if k == "off" else 0.0))
    if gen == "subsets":
        kk = f.get("k")
        if (isinstance(kk, bool) or not isinstance(kk, int) or not 1 <= kk <= len(acts)):
            raise r.fail(f"{where}.k", kk, f"an integer in [1, {len(acts)}] (subset size)")
        groups = list(itertools.combinations(acts, kk))
    else:
        groups = [(a,) for a in acts]
    sets: list[FaultSet] = []
    for grp in groups:
        for kind, loss in variants:
            triples = [(a, kind, loss) for a in grp]
            sets.append(FaultSet(fam, "+".join(_label(a, kind, loss) for a in grp),
                                 tuple(triples)))
    return FaultFamily(fam, tuple(sets))


def _listed_sets(r: _R, f: Mapping[str, Any], where: str, fam: str,
                 actuator_names: Sequence[str]) -> tuple[FaultSet, ...]:
    """The fault sets of a ``generate = "list"`` family (``sets``)."""
    sets: list[FaultSet] = []
    raw_sets = f.get("sets")
    if not isinstance(raw_sets, list) or not raw_sets:
        raise r.fail(f"{where}.sets", raw_sets, "a non-empty list of fault sets, each a "
                     "list of faults like \"rotor_2b:loss=0.5\"")
    for j, s in enumerate(raw_sets):
        at = f"{where}.sets[{j}]"
        if isinstance(s, str):
            s = [s]
        if not isinstance(s, list) or not s or not all(isinstance(x, str) for x in s):
            raise r.fail(at, s, "a non-empty list of faults like \"rotor_2b:loss=0.5\"")
        triples: list[tuple[str, str, float]] = []
        for txt in s:
            if "@" in txt:
                raise r.fail(at, txt, "a fault without '@TIME' (the injection time is "
                             "the phase axis)")
            try:
                flts = parse_fault_spec(txt, actuator_names)
            except FaultError as exc:
                raise SpecError(f"{r.source}: field '{at}' = {txt!r}: {exc}") from None
            triples += [(x.actuator, x.kind.value, float(x.loss)) for x in flts]
        sets.append(FaultSet(fam, " ".join(s), tuple(triples)))
    return tuple(sets)


def _magnitudes(r: _R, f: Mapping[str, Any], where: str, kinds: Sequence[str]) -> list[float]:
    """The ``magnitudes`` of a generated family (losses in (0, 1]; only with kind loss)."""
    mags: list[float] = []
    if "loss" in kinds:
        mraw = f.get("magnitudes")
        if not isinstance(mraw, list) or not mraw:
            raise r.fail(f"{where}.magnitudes", mraw, "a non-empty list of losses in (0, 1] "
                         "(kinds has loss)")
        for m in mraw:
            if (isinstance(m, bool) or not isinstance(m, int | float) or not math.isfinite(m)
                    or not 0.0 < m <= 1.0):
                raise r.fail(f"{where}.magnitudes", m, "a loss in (0, 1] (fraction of "
                             "effectiveness lost: 0.5 = 50 %)")
            mags.append(float(m))
    elif "magnitudes" in f:
        raise r.fail(f"{where}.magnitudes", f["magnitudes"],
                     "no magnitudes unless kinds has loss")
    return mags


def _label(actuator: str, kind: str, loss: float) -> str:
    return f"{actuator}:loss={loss:g}" if kind == "loss" else f"{actuator}:{kind}"


def _wind(r: _R, w: Any, i: int) -> WindSpec:
    where = f"wind[{i}]"
    r.keys(w, _WIND, where)
    name = r.string(w, "name", where)
    steady = r.vec3(w, "steady_ned_m_s", where, -MAX_WIND_M_S, MAX_WIND_M_S, " m/s (NED)",
                    (0.0, 0.0, 0.0))
    gusts = []
    graw = w.get("gusts", [])
    if not isinstance(graw, list):
        raise r.fail(f"{where}.gusts", graw, "a list of gust tables")
    for j, g in enumerate(graw):
        at = f"{where}.gusts[{j}]"
        r.keys(g, _GUST, at)
        if ("start_s" in g) == ("after_fault_s" in g):
            raise r.fail(at, g, "exactly one of start_s (absolute) or after_fault_s")
        start = r.number(g, "start_s", at, 0.0, 3600.0, " (s)") if "start_s" in g else None
        after = (r.number(g, "after_fault_s", at, -3600.0, 3600.0, " (s)")
                 if "after_fault_s" in g else None)
        dur = r.number(g, "duration_s", at, 0.0, 600.0, " (s)", open_lo=True)
        amp = r.vec3(g, "amplitude_ned_m_s", at, -MAX_WIND_M_S, MAX_WIND_M_S, " m/s (NED)",
                     (0.0, 0.0, 0.0))
        if "amplitude_ned_m_s" not in g:
            raise SpecError(f"{r.source}: missing field '{at}.amplitude_ned_m_s'")
        gusts.append(GustSpec(dur, amp, start, after))
    return WindSpec(name, steady, tuple(gusts))


def _pert(r: _R, p: Any, i: int) -> PerturbationSpec:
    where = f"perturbation[{i}]"
    r.keys(p, _PERT, where)
    name = r.string(p, "name", where)
    ms = r.number(p, "mass_scale", where, 0.5, 2.0, " (factor on the mass)", default=1.0)
    js = r.vec3(p, "inertia_scale", where, 0.5, 2.0, " (factors on Jx, Jy, Jz)",
                (1.0, 1.0, 1.0), scalar_ok=True)
    cg = r.vec3(p, "cg_offset_m", where, -0.5, 0.5, " m (body FRD)", (0.0, 0.0, 0.0))
    return PerturbationSpec(name, ms, js, cg)
