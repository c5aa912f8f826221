"""SHA-256 over every control step's actuator commands, to show a refactor changed nothing.

Flies paper case 1 with gs-shif, case 2 with shif and case 0 with lqr in-process (40 s each,
10,000 control steps) and prints one digest per run over the float64 bytes of the 15 commands
the autopilot sent at each step (after the float32 wire rounding). Two trees give the same
digests exactly when their flights are bit-identical::

    python benchmarks/command_digest.py
"""

from __future__ import annotations

import hashlib
from typing import Any

from vtolftc.protocols.hil import wire_commands
from vtolftc.runners.scenario import paper_scenario, run_scenario

RUNS = (("1", "gs-shif"), ("2", "shif"), ("0", "lqr"))


class _Digest:
    """A run observer hashing each sample's commands."""

    def __init__(self) -> None:
        self.h = hashlib.sha256()
        self.n = 0

    def on_start(self, info: dict[str, Any]) -> None:
        pass

    def on_sample(self, sample: Any) -> None:
        self.h.update(wire_commands(sample.status.actuator_commands).tobytes())
        self.n += 1

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        pass

    def on_finish(self, metrics: dict[str, Any]) -> None:
        pass


def main() -> None:
    """Print ``case controller steps digest`` for each run."""
    for case, controller in RUNS:
        d = _Digest()
        run_scenario(paper_scenario(case), controller, observers=[d])
        print(f"case {case} {controller:8s} steps {d.n} sha256 {d.h.hexdigest()}")


if __name__ == "__main__":
    main()
