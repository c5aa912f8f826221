"""Re-measure the paper's flight claims for a gains folder (in-process runs, deterministic).

    python docs/ds1-claims/measure.py --gains firmware_sim/autopilot/gains --label robust
    python docs/ds1-claims/measure.py --gains firmware_sim/autopilot/gains/paper --label paper

Runs (2 worker processes by default):

- table 4: the paper's cases 1 and 2, 40 s, GS-SHIF, SHIF and LQR; RMSE of roll, pitch, yaw
  over t >= 20 s (``vtolftc fly`` metrics);
- ``--only delay``: a nominal transition with 20, 25, 40 ms one-way HIL delay (GS-SHIF);
- survival: every single lift rotor off in hover (t = 15 s) and mid-transition (t = 24 s,
  about 6 m/s), elevator off / stuck in hover, mid-transition and cruise (t = 40 s), 60 s
  runs, per controller. A run *survives* when it did not crash (metrics: attitude beyond
  60 deg, ground contact, non-finite state) and ended within 5 m of the commanded altitude.

Every record also carries ``commands_sha256``: the sha256 over every control step's actuator
commands as the wire carries them (``benchmarks/command_digest.py``'s digest), so a record
names the exact flight it measured. ``benchmarks/regen_docs.py`` runs these flights for every
results file of this folder and stamps them (``PROVENANCE.json``).

Writes ``<out>/<label>.json`` (all metrics) and prints markdown tables.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROTORS = ("1a", "1b", "2a", "2b", "3a", "3b", "4a", "4b")
HOVER_S, TRANSITION_S, CRUISE_S = 15.0, 24.0, 40.0
KEYS = ("crashed", "crash_time_s", "rmse_roll_deg", "rmse_pitch_deg", "rmse_yaw_deg",
        "rmse_altitude_m", "max_abs_roll_error_deg", "max_abs_pitch_error_deg",
        "max_abs_yaw_error_deg", "final_altitude_error_m", "final_airspeed_m_s",
        "transition_complete_s", "quad_chute")


def survival_cases() -> list[tuple[str, str, list[str]]]:
    out = []
    for ph, t in (("hover", HOVER_S), ("transition", TRANSITION_S)):
        out += [(f"rotor {r} off, {ph}", "0", [f"rotor_{r}:off@{t:g}"]) for r in ROTORS]
    for ph, t in (("hover", HOVER_S), ("transition", TRANSITION_S), ("cruise", CRUISE_S)):
        out += [(f"elevator {k}, {ph}", "0", [f"elevator:{k}@{t:g}"]) for k in ("off", "stuck")]
    return out


class PeakAttitude:
    """Observer: largest |roll| and |pitch| [deg] from ``t0_s`` on (the excursion a fault
    causes; the metrics' max errors only cover t >= 20 s)."""

    def __init__(self, t0_s: float) -> None:
        self.t0_usec = round(t0_s * 1e6)
        self.roll = self.pitch = 0.0

    def on_start(self, info: dict[str, Any]) -> None:
        pass

    def on_sample(self, sample: Any) -> None:
        if sample.time_usec >= self.t0_usec:
            from vtolftc.firmware_sim.autopilot.autopilot import quat_to_euler

            r, p, _ = quat_to_euler(sample.nav.q_wxyz)
            self.roll = max(self.roll, abs(math.degrees(r)))
            self.pitch = max(self.pitch, abs(math.degrees(p)))

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        pass

    def on_finish(self, metrics: dict[str, Any]) -> None:
        pass


class CommandDigest:
    """Observer: sha256 over the float64 bytes of every control step's actuator commands after
    the float32 wire rounding (the digest of ``benchmarks/command_digest.py``)."""

    def __init__(self) -> None:
        self.h = hashlib.sha256()

    def on_start(self, info: dict[str, Any]) -> None:
        pass

    def on_sample(self, sample: Any) -> None:
        from vtolftc.protocols.hil import wire_commands

        self.h.update(wire_commands(sample.status.actuator_commands).tobytes())

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        pass

    def on_finish(self, metrics: dict[str, Any]) -> None:
        pass


def fly(job: tuple[str, str, list[str], str, str | None, float, float]) -> dict[str, Any]:
    label, case, specs, ctrl, gains, duration, delay = job
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.vehicle.faults import parse_fault_spec
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    af = load_airframe()
    faults = [f for s in specs for f in parse_fault_spec(s, af.actuator_names)]
    sc = paper_scenario(case, duration, airframe=af, extra_faults=faults)
    # peak attitude from the fault on, or (no fault: delay runs) from just after the arm
    t0 = min((f.start_s for f in faults), default=1.5)
    peak = PeakAttitude(t0)
    digest = CommandDigest()
    m = run_scenario(sc, ctrl, airframe=af, gains_dir=gains, hil_delay_s=delay,
                     observers=[peak, digest]).metrics
    out = {k: m.get(k) for k in KEYS}
    out["peak_roll_deg"], out["peak_pitch_deg"] = peak.roll, peak.pitch
    err = out["final_altitude_error_m"]
    out["survived"] = bool(not out["crashed"] and err is not None and abs(err) <= 5.0)
    out["commands_sha256"] = digest.h.hexdigest()
    return {"label": label, "controller": ctrl, **out}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gains", default=None, help="gains folder (default: shipped)")
    ap.add_argument("--label", required=True, help="name of the result file")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent))
    ap.add_argument("--controllers", default="gs-shif,shif,lqr",
                    help="controllers of the table 4 runs")
    ap.add_argument("--survival-controllers", default=None,
                    help="controllers of the survival runs (default: --controllers)")
    ap.add_argument("--only", choices=("all", "table4", "survival", "delay"), default="all",
                    help="delay: nominal transition (case 0, 45 s) with 20, 25 and 40 ms one-way "
                         "HIL delay, GS-SHIF (not part of all)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--delays-ms", default="20,25,40",
                    help="one-way HIL delays of --only delay, ms (default 20,25,40)")
    a = ap.parse_args(argv)
    ctrls = a.controllers.split(",")
    sctrls = (a.survival_controllers or a.controllers).split(",")
    jobs: list[tuple[Any, ...]] = []
    if a.only in ("all", "table4"):
        jobs += [(f"case {c}", c, [], k, a.gains, 40.0, 0.0) for c in ("1", "2") for k in ctrls]
    if a.only in ("all", "survival"):
        jobs += [(lab, c, s, k, a.gains, 60.0, 0.0) for k in sctrls
                 for lab, c, s in survival_cases()]
    if a.only == "delay":
        jobs = [(f"delay {d:g} ms", "0", [], "gs-shif", a.gains, 45.0, d * 1e-3)
                for d in (float(x) for x in a.delays_ms.split(","))]
    with ProcessPoolExecutor(a.jobs) as ex:
        results = []
        for r in ex.map(fly, jobs):
            results.append(r)
            print(f"{r['controller']:8s} {r['label']:26s} "
                  f"{'survived' if r['survived'] else 'LOST'} "
                  f"crash={r['crashed']} altE={r['final_altitude_error_m']}", flush=True)
    path = Path(a.out) / f"{a.label}.json"
    from vtolftc.base.jsonio import json_safe

    path.write_text(json.dumps(json_safe(results), indent=1, allow_nan=False) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
