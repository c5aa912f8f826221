"""Actuator faults applied to the physical actuators of the simulated vehicle.

A :class:`Fault` names one actuator (``rotor_2b``, ``pusher_left``, ``elevator``,
``aileron_left`` ...), a kind and a start time in simulated seconds:

- ``loss``: partial loss of effectiveness, ``loss`` in [0, 1]; the actuator's physical output
  (thrust, or effective deflection) is multiplied by ``1 - loss``;
- ``off``: the actuator produces nothing (same as ``loss = 1``);
- ``stuck``: the actuator's position freezes at its value when the fault starts.

Faults compose: two losses on one actuator multiply their remaining effectiveness, a stuck
actuator can also have lost effectiveness. The controller never sees any of this (passive
FTC): faults live only in the vehicle.

Group names expand to several actuators: ``ailerons``, ``rudders``, ``surfaces``,
``lift_rotors``, ``pushers``. The paper's cases 1 and 2 are data in ``fault_cases.toml``.
"""

from __future__ import annotations

import difflib
import math
import re
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

CASES_PATH = Path(__file__).with_name("fault_cases.toml")


class FaultError(ValueError):
    """A bad fault specification: the message says what was wrong and what is accepted."""


class FaultKind(StrEnum):
    """What happens to the actuator: partial effectiveness loss, switched off, or stuck."""
    LOSS = "loss"
    OFF = "off"
    STUCK = "stuck"


@dataclass(frozen=True)
class Fault:
    """One fault on one physical actuator, active from ``start_s`` (simulated seconds)."""

    actuator: str
    kind: FaultKind = FaultKind.LOSS
    loss: float = 0.0
    start_s: float = 0.0

    def __post_init__(self) -> None:
        try:
            kind = FaultKind(self.kind)
        except ValueError:
            raise FaultError(
                f"fault on {self.actuator!r}: unknown kind {self.kind!r}: expected one of "
                f"{', '.join(k.value for k in FaultKind)}"
            ) from None
        object.__setattr__(self, "kind", kind)
        if not isinstance(self.actuator, str) or not self.actuator:
            raise FaultError(f"fault actuator {self.actuator!r}: expected an actuator name")
        loss = self.loss
        if isinstance(loss, bool) or not isinstance(loss, int | float) or not math.isfinite(loss):
            raise FaultError(f"fault on {self.actuator!r}: loss {loss!r}: expected a number "
                             "in [0, 1] (fraction of effectiveness lost)")
        if not 0.0 <= float(loss) <= 1.0:
            raise FaultError(f"fault on {self.actuator!r}: loss {loss!r}: expected a fraction "
                             "in [0, 1] (0.5 = 50 % loss), not a percentage")
        if kind is FaultKind.OFF:
            object.__setattr__(self, "loss", 1.0)
        start = self.start_s
        if isinstance(start, bool) or not isinstance(start, int | float) or not (
                math.isfinite(start) and start >= 0.0):
            raise FaultError(f"fault on {self.actuator!r}: start time {start!r}: expected a "
                             "time >= 0 in simulated seconds")

    @property
    def effectiveness(self) -> float:
        """Remaining fraction of the actuator's output, 1 - loss."""
        return 1.0 - float(self.loss)

    @property
    def start_usec(self) -> int:
        """Fault onset in simulated time (us)."""
        return round(self.start_s * 1e6)

    def describe(self) -> str:
        """One line for logs, e.g. ``rotor_2b: 50% loss from t = 20 s``."""
        what = f"{self.loss:.0%} loss" if self.kind is FaultKind.LOSS else self.kind.value
        return f"{self.actuator}: {what} from t = {self.start_s:g} s"


GROUPS: dict[str, tuple[str, ...]] = {
    "ailerons": ("aileron_left", "aileron_right"),
    "rudders": ("rudder_left", "rudder_right"),
    "surfaces": ("aileron_left", "aileron_right", "elevator", "rudder_left", "rudder_right"),
}


def expand_actuators(names: Iterable[str], actuator_names: Sequence[str]) -> list[str]:
    """Expand group names and check every name against the airframe's actuators."""
    groups = dict(GROUPS)
    for g, prefix in (("ailerons", "aileron"), ("rudders", "rudder")):
        groups[g] = tuple(n for n in actuator_names if n.startswith(prefix))
    groups["surfaces"] = tuple(n for n in actuator_names
                               if not n.startswith(("rotor_", "pusher_")))
    groups["lift_rotors"] = tuple(n for n in actuator_names if n.startswith("rotor_"))
    groups["pushers"] = tuple(n for n in actuator_names if n.startswith("pusher_"))
    out: list[str] = []
    for name in names:
        if name in groups:
            out.extend(groups[name])
        elif name in actuator_names:
            out.append(name)
        else:
            choices = list(actuator_names) + list(groups)
            near = difflib.get_close_matches(name, choices, n=3)
            hint = f" (did you mean {' or '.join(near)}?)" if near else ""
            raise FaultError(
                f"unknown actuator {name!r}{hint}; known actuators: {', '.join(actuator_names)}"
                f"; groups: {', '.join(groups)}"
            )
    return out


_SPEC = re.compile(
    r"^\s*(?P<act>[A-Za-z0-9_]+)\s*:\s*(?P<kind>loss|off|stuck)"
    r"(?:\s*=\s*(?P<val>[-+0-9.eE]+)(?P<pct>%)?)?\s*(?:@\s*(?P<t>[-+0-9.eE]+)\s*s?)?\s*$"
)


def parse_fault_spec(text: str, actuator_names: Sequence[str]) -> list[Fault]:
    """Parse ``ACTUATOR:KIND[=VALUE][@START]``, e.g. ``rotor_2b:loss=0.5@22``,
    ``ailerons:loss=20%@22``, ``elevator:stuck@10``, ``rotor_1a:off``."""
    m = _SPEC.match(text)
    if not m:
        raise FaultError(
            f"cannot read fault {text!r}: expected ACTUATOR:KIND[=VALUE][@START_S], e.g. "
            "rotor_2b:loss=0.5@22 or elevator:stuck@10 (kinds: loss, off, stuck)"
        )
    kind = FaultKind(m["kind"])
    loss = 0.0
    if kind is FaultKind.LOSS:
        if m["val"] is None:
            raise FaultError(f"fault {text!r}: a loss needs a value, e.g. loss=0.5 or loss=50%")
        try:
            loss = float(m["val"]) / (100.0 if m["pct"] else 1.0)
        except ValueError:
            raise FaultError(f"fault {text!r}: loss {m['val']!r} is not a number") from None
    elif m["val"] is not None:
        raise FaultError(f"fault {text!r}: kind {kind.value!r} takes no value")
    try:
        start = float(m["t"]) if m["t"] is not None else 0.0
    except ValueError:
        raise FaultError(f"fault {text!r}: start time {m['t']!r} is not a number") from None
    return [Fault(a, kind, loss, start) for a in expand_actuators([m["act"]], actuator_names)]


def faults_from_records(
    records: Iterable[Mapping[str, Any]], actuator_names: Sequence[str], where: str = "faults"
) -> list[Fault]:
    """Build faults from records ``{actuators = [...], kind, loss, start_s}`` (TOML/JSON)."""
    out: list[Fault] = []
    allowed = {"actuators", "kind", "loss", "start_s"}
    for i, rec in enumerate(records):
        at = f"{where}[{i}]"
        if not isinstance(rec, Mapping):
            raise FaultError(f"{at}: expected a table with actuators, kind, loss, start_s")
        unknown = set(rec) - allowed
        if unknown:
            raise FaultError(f"{at}: unknown key(s) {sorted(unknown)}: expected {sorted(allowed)}")
        acts = rec.get("actuators")
        if isinstance(acts, str):
            acts = [acts]
        if not isinstance(acts, list) or not acts or not all(isinstance(a, str) for a in acts):
            raise FaultError(f"{at}.actuators = {acts!r}: expected a list of actuator names")
        kind = rec.get("kind", "loss")
        loss = rec.get("loss", 0.0)
        start = rec.get("start_s", 0.0)
        try:
            for name in expand_actuators(acts, actuator_names):
                out.append(Fault(name, kind, loss, start))
        except FaultError as exc:
            raise FaultError(f"{at}: {exc}") from None
    return out


def load_cases(path: str | Path | None = None) -> dict[str, dict[str, Any]]:
    """The raw fault-case table (``case1``, ``case2`` ...) of a cases file."""
    p = CASES_PATH if path is None else Path(path)
    try:
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise FaultError(f"{p}: cannot read the fault-case file ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise FaultError(f"{p}: not valid TOML: {exc}") from None
    return doc


def case_faults(case: str | int, actuator_names: Sequence[str], path: str | Path | None = None,
                ) -> list[Fault]:
    """The faults of a named case (``1``, ``"case2"`` ...), checked against the airframe."""
    doc = load_cases(path)
    key = f"case{case}" if not str(case).startswith("case") else str(case)
    if key not in doc:
        raise FaultError(f"unknown fault case {case!r}: known cases: "
                         f"{', '.join(k.removeprefix('case') for k in doc)}")
    entry = doc[key]
    return faults_from_records(entry.get("fault", []), actuator_names, where=f"{key}.fault")


def case_description(case: str | int, path: str | Path | None = None) -> str:
    """The ``description`` of fault case ``case`` (3 or "case3") in the cases file, or ""."""
    doc = load_cases(path)
    key = f"case{case}" if not str(case).startswith("case") else str(case)
    return str(doc.get(key, {}).get("description", ""))
