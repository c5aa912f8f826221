"""Before/after check of the real-parametric certificate (``synthesis/certificate.py``).

``dump`` runs :func:`vtolftc.synthesis.certificate.certify_schedule` on every shipped gain
schedule (robust and paper GS-SHIF / SHIF, each on its design plant, the paper's also on the
lagged plant: the runs of ``docs/ds1-claims/certificate.py``) and writes the records to a
JSON file; ``compare`` prints the largest relative change of every number (the mu bounds of
every piece, the grid, the margins) between two dumps and whether any verdict changed.

    python benchmarks/certificate_regression.py dump before.json
    python benchmarks/certificate_regression.py compare before.json after.json

``--base DIR`` (dump) imports ``vtolftc.synthesis`` from another checkout's ``synthesis``
folder (e.g. an unpacked ``git archive``), so both sides run in the same session.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
GAINS = ROOT / "firmware_sim" / "autopilot" / "gains"
RUNS = (("robust", GAINS, "lagged"), ("paper", GAINS / "paper", "paper"),
        ("paper-on-lagged", GAINS / "paper", "lagged"))


def dump(out: Path, base: Path | None) -> int:
    if base is not None:
        import vtolftc.synthesis as syn

        syn.__path__[:] = [str(base)]
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis import certificate as cert

    af = load_airframe()
    recs: list[dict[str, Any]] = []
    for label, gdir, plant in RUNS:
        for ctrl in ("gs-shif", "shif"):
            doc = json.loads((gdir / f"{ctrl}.json").read_text())
            t0 = time.perf_counter()
            rs = cert.certify_schedule(af, doc, plant)  # type: ignore[arg-type]
            dt = time.perf_counter() - t0
            for r in rs:
                r.update(label=label, controller=ctrl)
            recs += rs
            print(f"{label} {ctrl}: {dt:.1f} s ({dt / len(rs):.2f} s per axis-point)",
                  flush=True)
    out.write_text(json.dumps({"module": cert.__file__, "records": recs}, indent=1))
    return 0


def _flat(x: Any, key: str, out: dict[str, Any]) -> None:
    if isinstance(x, dict):
        for k, v in x.items():
            _flat(v, f"{key}.{k}", out)
    elif isinstance(x, list):
        for i, v in enumerate(x):
            _flat(v, f"{key}[{i}]", out)
    else:
        out[key] = x


def compare(a: Path, b: Path) -> int:
    ra, rb = (json.loads(p.read_text())["records"] for p in (a, b))
    if len(ra) != len(rb):
        print(f"different record counts: {len(ra)} vs {len(rb)}", file=sys.stderr)
        return 2
    worst: dict[str, tuple[float, str]] = {}
    verdicts = 0
    for x, y in zip(ra, rb, strict=True):
        name = f"{x['label']} {x['controller']} {x['axis']} {x['point']}"
        if x["verdict"] != y["verdict"]:
            verdicts += 1
            print(f"VERDICT CHANGED {name}: {x['verdict']} -> {y['verdict']}")
        fx: dict[str, Any] = {}
        fy: dict[str, Any] = {}
        _flat(x, "", fx)
        _flat(y, "", fy)
        for k, vx in fx.items():
            vy = fy.get(k)
            field = k.split(".")[-1]
            if isinstance(vx, bool) or not isinstance(vx, (int, float)):
                if vx != vy:
                    worst[field] = (math.inf, f"{name} {k}: {vx} -> {vy}")
                continue
            if not isinstance(vy, (int, float)):
                worst[field] = (math.inf, f"{name} {k}: {vx} -> {vy}")
                continue
            d = abs(vy - vx) / max(abs(vx), 1e-12) if vx != vy else 0.0
            if d > worst.get(field, (-1.0, ""))[0]:
                worst[field] = (d, f"{name} {k}: {vx!r} -> {vy!r}")
    print(f"{len(ra)} axis-points, {verdicts} verdict changes")
    for field, (d, where) in sorted(worst.items()):
        print(f"  {field:28s} max rel change {d:9.2e}   {where if d > 0 else ''}")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump", help="certify every shipped schedule, write JSON")
    d.add_argument("out", type=Path)
    d.add_argument("--base", type=Path, help="synthesis folder to import instead")
    c = sub.add_parser("compare", help="largest relative change between two dumps")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args()
    if args.cmd == "dump":
        if args.base is not None and not (args.base / "certificate.py").exists():
            print(f"--base {args.base}: no certificate.py there; give a synthesis folder",
                  file=sys.stderr)
            return 2
        return dump(args.out, args.base)
    for p in (args.a, args.b):
        if not p.exists():
            print(f"{p}: no such file; run 'dump' first", file=sys.stderr)
            return 2
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
