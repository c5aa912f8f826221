"""The real-parametric robust-stability certificate of both DS-1 designs (issue 11, part 3).

For every design (paper, robust), controller (GS-SHIF per-point gains, SHIF constant gains),
design point and axis: the lumped complex mu_RS the gain file records (table 3 form), the
mixed-mu upper bound (D-G scaling) and lower bound of the real parametric family
(airspeed x gamma box of the point), and the dense-grid verdict (closed-loop poles of the
true model family over 41 x 41 V x gamma, the largest real part, the grid margin)
(:mod:`vtolftc.synthesis.certificate`). Writes ``CERTIFICATE.md`` and ``certificate.json``
beside this script (the JSON after every schedule, so an interrupted run keeps what it has).

    python docs/ds1-claims/certificate.py                 # ~5-10 min on 2 shared cores
    python docs/ds1-claims/certificate.py --only robust   # one design

Plants: each design on its own design plant (robust: eq. 1-3 + actuator lag with the 8 ms
loop delay folded in; paper: eq. 1-3 alone), and the paper's gains also on the robust
design plant (the loop that flies).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

from vtolftc.airframe.loader import load_airframe
from vtolftc.base.jsonio import atomic_write_text
from vtolftc.synthesis.certificate import certify_schedule

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
GAINS = ROOT / "firmware_sim" / "autopilot" / "gains"

#: (label, design, gain directory, plant)
RUNS: tuple[tuple[str, str, Path, str], ...] = (
    ("robust", "robust", GAINS, "lagged"),
    ("paper", "paper", GAINS / "paper", "paper"),
    ("paper-on-lagged", "paper", GAINS / "paper", "lagged"),
)
PLANT_TEXT = {"lagged": "eq. 1-3 + lag 1/((tau_act + 8 ms) s + 1)", "paper": "eq. 1-3"}


def _write_json(path: Path, doc: Any) -> None:
    atomic_write_text(path, json.dumps(doc, indent=1, allow_nan=False))


def _f(x: Any, nd: int = 3) -> str:
    if x is None:
        return "-"
    if isinstance(x, float) and not math.isfinite(x):
        return "inf"
    return f"{x:.{nd}f}"


def table(records: list[dict[str, Any]]) -> list[str]:
    """Markdown rows of the certificate table."""
    out = ["| design | controller | plant | axis | No. | V [m/s] | lumped mu_RS (table 3) | "
           "mixed mu upper | mixed mu lower | grid (41x41) | max Re pole [1/s] | "
           "grid mu = 1/k | verdict |",
           "|---|---|---|---|---|---|---:|---:|---:|---|---:|---:|---|"]
    for r in records:
        grid = "stable" if r["grid_stable"] else (
            f"**unstable** ({r['grid_unstable_members']}/{r['grid_members']}, worst "
            f"V {r['grid_worst_airspeed_m_s']:.2f}, gamma {r['grid_worst_gamma']:.2f})")
        verdict = r["verdict"] if r["certified"] else f"**{r['verdict']}**"
        if not r.get("centre_stable", True):   # mu infinite: the nominal itself is unstable
            r = {**r, "mu_upper": math.inf, "mu_lower": math.inf, "grid_mu": math.inf}
        out.append(
            f"| {r['label']} | {r['controller']} | {r['plant']} | {r['axis']} | {r['point']} | "
            f"{r['v_min_m_s']:g}-{r['v_max_m_s']:g} | {_f(r['lumped_mu_rs'])} | "
            f"{_f(r['mu_upper'])} | {_f(r['mu_lower'])} | {grid} | "
            f"{r['grid_max_real_pole_rad_s']:.3f} | {_f(r['grid_mu'])} | {verdict} |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=[r[0] for r in RUNS], action="append",
                    help="run only this design label (repeatable)")
    ap.add_argument("--out", type=Path, default=HERE, help="output directory")
    ap.add_argument("--render", action="store_true",
                    help="only rewrite CERTIFICATE.md from the existing certificate.json")
    args = ap.parse_args(argv)
    if not args.out.is_dir():
        print(f"--out {args.out}: not a directory; give an existing directory",
              file=sys.stderr)
        return 2
    jpath = args.out / "certificate.json"
    if args.render:
        if not jpath.exists():
            print(f"--render: {jpath} does not exist; run without --render first",
                  file=sys.stderr)
            return 2
        render(args.out, json.loads(jpath.read_text())["records"])
        return 0
    af = load_airframe()
    records: list[dict[str, Any]] = []
    times: dict[str, float] = {}
    for label, design, gdir, plant in RUNS:
        if args.only and label not in args.only:
            continue
        for ctrl in ("gs-shif", "shif"):
            doc = json.loads((gdir / f"{ctrl}.json").read_text())
            t0 = time.perf_counter()
            recs = certify_schedule(af, doc, plant)  # type: ignore[arg-type]
            dt = time.perf_counter() - t0
            times[f"{label} {ctrl}"] = dt
            for r in recs:
                r.update(label=label, design=design, controller=ctrl,
                         gain_file=str((gdir / f"{ctrl}.json").relative_to(ROOT)))
            records += recs
            print(f"{label} {ctrl}: {len(recs)} axis-points in {dt:.1f} s "
                  f"({dt / len(recs):.2f} s each)", flush=True)
            _write_json(jpath, {"format": "vtolftc-certificate/1", "plants": PLANT_TEXT,
                                "seconds": times, "records": records})
    render(args.out, records)
    print(f"wrote {jpath}")
    return 0


def summary(records: list[dict[str, Any]]) -> list[str]:
    """Markdown rows: per design and controller, how many axis-points each test passes."""
    out = ["| design | controller | plant | axis-points | lumped mu_RS < 1 | mixed mu upper < 1 "
           "(certified) | grid stable | not certified |",
           "|---|---|---|---:|---:|---:|---:|---|"]
    keys: list[tuple[str, str]] = []
    for r in records:
        if (r["label"], r["controller"]) not in keys:
            keys.append((r["label"], r["controller"]))
    for label, ctrl in keys:
        rs = [r for r in records if r["label"] == label and r["controller"] == ctrl]
        lumped = sum(1 for r in rs if r["lumped_mu_rs"] is not None and r["lumped_mu_rs"] < 1)
        cert = sum(1 for r in rs if r["certified"])
        grid = sum(1 for r in rs if r["grid_stable"])
        bad = ", ".join(
            f"{r['axis']} {r['point']} ("
            + (_f(r["mu_upper"], 2) if r.get("centre_stable", True) else "centre unstable")
            + ")" for r in rs if not r["certified"]) or "-"
        out.append(f"| {label} | {ctrl} | {rs[0]['plant']} | {len(rs)} | {lumped} | {cert} | "
                   f"{grid} | {bad} |")
    return out


def render(out: Path, records: list[dict[str, Any]]) -> None:
    """CERTIFICATE.md: the text of ``certificate_head.md``, the summary and the table."""
    md = out / "CERTIFICATE.md"
    head = HERE / "certificate_head.md"
    text = head.read_text() if head.exists() else "# Certificate\n"
    md.write_text(text.rstrip() + "\n\n## Summary (generated)\n\n" + "\n".join(summary(records))
                  + "\n\n## Every axis-point (generated)\n\n" + "\n".join(table(records))
                  + "\n")
    print(f"wrote {md}")


if __name__ == "__main__":
    sys.exit(main())
