"""Regenerate the results files of ``docs/ds1-claims/`` on today's code, and stamp them.

    nice -n 5 python benchmarks/regen_docs.py                      # everything (~30 min, 2 jobs)
    nice -n 5 python benchmarks/regen_docs.py --files table3.json robust.json paper.json
    python benchmarks/regen_docs.py --list                         # the files and their runs

Each results file is computed here (the flights through ``docs/ds1-claims/measure.py``'s
``fly``, in-process and deterministic; table 3 from the gain files), written, and stamped in
``docs/ds1-claims/PROVENANCE.json`` (:mod:`vtolftc.base.provenance`): the command that made
it, the sha256 of the gain files and airframe file it used, the digest of its records and,
for flights, the digest of every flight's actuator commands. After the files,
``docs/ds1-claims/tables.py`` rewrites ``TABLES.md`` and ``rmse.png``.
``tests/test_docs_provenance.py`` fails when a stamped input (a gain file) changes, when a
results file is edited without its stamp, and (slow) when the code no longer flies the
stamped numbers.

The synthesis reports (``docs/ds1-synthesis/``, ``docs/ds1-synthesis-robust/``) are written
by ``vtolftc synth`` together with the gain files (``firmware_sim/autopilot/gains/README.md``),
the single-rotor campaign figures (``docs/campaigns/single-rotor/``) by ``vtolftc campaign``;
``--stamp FOLDER`` stamps such a folder's files as they are, with the inputs they were made
from, right after they were copied in (the test checks that the synthesis reports' mu tables
agree with the gain files).

The certificate (``certificate.json``, ``CERTIFICATE.md``) is written by
``docs/ds1-claims/certificate.py`` (5-10 min); ``--files certificate.json`` runs it and
stamps its output.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from vtolftc.base.jsonio import atomic_write_text, json_safe
from vtolftc.base.provenance import FORMAT, SIDECAR, make_file_stamp, make_stamp

ROOT = Path(__file__).resolve().parents[1]
CLAIMS = ROOT / "docs" / "ds1-claims"
GAINS = ROOT / "firmware_sim" / "autopilot" / "gains"
AIRFRAME = ROOT / "airframe" / "ds1.toml"
AXES = ("roll", "pitch", "yaw")
#: the two designs: label -> gains folder
DESIGNS = {"paper": GAINS / "paper", "robust": GAINS}

_MEASURE: ModuleType | None = None


def measure() -> ModuleType:
    """``docs/ds1-claims/measure.py`` as a module (loaded once per process)."""
    global _MEASURE
    if _MEASURE is None:
        spec = importlib.util.spec_from_file_location("ds1_claims_measure",
                                                      CLAIMS / "measure.py")
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        _MEASURE = mod
    return _MEASURE


def fly(job: tuple[Any, ...]) -> dict[str, Any]:
    """One flight record of ``measure.fly`` as it is written (NaN and infinities as None, the
    project's JSON convention; picklable entry point for the pool)."""
    return json_safe(measure().fly(job))


# ------------------------------------------------------------------------------ the files
Job = tuple[str, str, list[str], str, str | None, float, float]


@dataclass
class Target:
    """One results file: its flights (or a function computing its document) and inputs."""

    name: str
    inputs: list[Path]
    jobs: list[Job] = field(default_factory=list)
    compute: Callable[[], Any] | None = None


def _gains(design: str, ctrls: list[str] | tuple[str, ...]) -> list[Path]:
    return [DESIGNS[design] / f"{c}.json" for c in ctrls] + [AIRFRAME]


def table4_jobs(design: str, ctrls: tuple[str, ...] = ("gs-shif", "shif", "lqr"),
                cases: tuple[str, ...] = ("1", "2")) -> list[Job]:
    """Table 4 flights (paper cases, 40 s) of one design, in the files' order."""
    g = None if design == "robust" else str(DESIGNS[design])
    return [(f"case {c}", c, [], k, g, 40.0, 0.0) for c in cases for k in ctrls]


def survival_jobs(design: str, ctrls: tuple[str, ...]) -> list[Job]:
    """Single-fault survival flights (60 s) of one design."""
    g = None if design == "robust" else str(DESIGNS[design])
    return [(lab, c, s, k, g, 60.0, 0.0) for k in ctrls
            for lab, c, s in measure().survival_cases()]


def delay_jobs(design: str, delays_ms: tuple[float, ...]) -> list[Job]:
    """Nominal transitions (case 0, 45 s, GS-SHIF) with a one-way HIL delay."""
    g = None if design == "robust" else str(DESIGNS[design])
    return [(f"delay {d:g} ms", "0", [], "gs-shif", g, 45.0, d * 1e-3) for d in delays_ms]


def table3_records(paper_margins: bool = True) -> list[dict[str, Any]]:
    """Table 3 of both designs from their GS-SHIF gain files.

    mu_Delta (robust stability) and mu_Delta-hat (robust performance) are the upper bounds
    the synthesis recorded in the gain file (``axes.<axis>.metadata.mu``). The delay margin
    [ms] is the extra loop delay that destabilises: for the robust design the gain file's
    (design plant at the centred nominal), for the paper design computed here on the robust
    method's design plant at the healthy nominal (``docs/ds1-claims/margins.py``); with
    ``paper_margins`` False those are left out (the rest is read from the files, no
    computation).
    """
    out = []
    for design, folder in DESIGNS.items():
        doc = json.loads((folder / "gs-shif.json").read_text())
        bp = doc["airspeed_breakpoints_m_s"]
        for ax in AXES:
            t = doc["axes"][ax]
            mus = t["metadata"]["mu"]
            for i, v in enumerate(bp):
                rec = {"design": design, "axis": ax, "point": i + 1, "airspeed_m_s": v,
                       "mu_rs": mus[i]["mu_rs"], "mu_rp": mus[i]["mu_rp"]}
                if design == "robust":
                    lm = t["metadata"]["loop_margins"][i]
                    rec["delay_margin_ms"] = lm["delay_margin_s"] * 1e3
                elif paper_margins:
                    g = {k: t[k][i] for k in ("kp_angle", "kp_rate", "ki_rate", "kd_rate",
                                              "tf_rate_s")}
                    rec["delay_margin_ms"] = _paper_delay_margin_s(ax, v, g) * 1e3
                out.append(rec)
    return out


def _paper_delay_margin_s(axis: str, airspeed_m_s: float, gains: dict[str, float]) -> float:
    """Delay margin [s] of one P-PID on the robust design plant, healthy, at ``airspeed``."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.robust import design_plant, loop_margins

    af = load_airframe(AIRFRAME)
    return float(loop_margins(design_plant(af, axis, airspeed_m_s, 0.0), gains).delay_margin_s)


def targets() -> dict[str, Target]:
    """Every results file of ``docs/ds1-claims`` this script writes, in run order."""
    all3 = ("gs-shif", "shif", "lqr")
    return {t.name: t for t in (
        Target("table3.json", [GAINS / "gs-shif.json", GAINS / "paper" / "gs-shif.json",
                               AIRFRAME], compute=table3_records),
        Target("robust.json", _gains("robust", all3),
               table4_jobs("robust") + survival_jobs("robust", ("shif", "lqr"))),
        Target("paper.json", _gains("paper", all3),
               table4_jobs("paper") + survival_jobs("paper", all3)),
        Target("robust-gs-shif.json", _gains("robust", ("gs-shif",)),
               survival_jobs("robust", ("gs-shif",))),
        Target("robust-delay.json", _gains("robust", ("gs-shif",)),
               delay_jobs("robust", (0, 20, 25, 40))),
        Target("robust-delay-long.json", _gains("robust", ("gs-shif",)),
               delay_jobs("robust", (60, 80))),
        Target("paper-delay.json", _gains("paper", ("gs-shif",)),
               delay_jobs("paper", (0, 20, 25, 40))),
        Target("paper-delay-long.json", _gains("paper", ("gs-shif",)),
               delay_jobs("paper", (60, 80))),
        Target("certificate.json", [GAINS / f"{c}.json" for c in ("gs-shif", "shif")]
               + [GAINS / "paper" / f"{c}.json" for c in ("gs-shif", "shif")] + [AIRFRAME],
               compute=_certificate),
    )}


#: report folder copied in from a CLI command -> (the command, the gains design it used, any
#: further input files)
REPORTS: dict[str, tuple[str, str, tuple[Path, ...]]] = {
    "docs/ds1-synthesis": (
        "vtolftc synth --method paper --airframe airframe/ds1.toml --out synth_paper --jobs 2 "
        "--seed 0 (report/ copied here, gains to firmware_sim/autopilot/gains/paper/)",
        "paper", ()),
    "docs/ds1-synthesis-robust": (
        "vtolftc synth --airframe airframe/ds1.toml --out synth_out --jobs 2 --seed 0 "
        "(report/ copied here, gains to firmware_sim/autopilot/gains/)", "robust", ()),
    "docs/campaigns/single-rotor": (
        "vtolftc campaign campaigns/single-rotor.toml --out runs/single-rotor --jobs 2 "
        "(the figures copied here)", "robust", (ROOT / "campaigns" / "single-rotor.toml",)),
}


def stamp_reports(folders: list[str]) -> None:
    """Stamp every file of the report ``folders`` (keys of :data:`REPORTS`) with its inputs."""
    for rel in folders:
        command, design, extra = REPORTS[rel]
        folder = ROOT / rel
        inputs = [*_gains(design, ("gs-shif", "shif", "lqr")), *extra]
        for path in sorted(p for p in folder.iterdir() if p.is_file() and p.name != SIDECAR):
            write_stamp(folder, path.name,
                        make_file_stamp(path, command=command, inputs=inputs, root=ROOT))
        print(f"stamped {rel}", flush=True)


def _certificate() -> Any:
    subprocess.run([sys.executable, str(CLAIMS / "certificate.py")], check=True, cwd=ROOT)
    return json.loads((CLAIMS / "certificate.json").read_text())


# ------------------------------------------------------------------------------ writing
def _git_commit() -> str | None:
    try:
        r = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True,
                           text=True, timeout=30, check=True)
        return r.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None


def write_stamp(folder: Path, name: str, stamp: dict[str, Any]) -> None:
    """Put ``stamp`` for ``name`` into ``folder/PROVENANCE.json`` (atomic rewrite)."""
    side = folder / SIDECAR
    prov = json.loads(side.read_text()) if side.is_file() else {}
    prov = {"format": FORMAT,
            "about": "one stamp per results file of this folder: the command that made it, "
                     "the sha256 of its inputs (gain files, airframe), the digest of its "
                     "records (JSON) or bytes, and of its flights' actuator commands; "
                     "checked by tests/test_docs_provenance.py (vtolftc.base.provenance)",
            "files": dict(prov.get("files", {}))}
    prov["files"][name] = stamp
    prov["files"] = dict(sorted(prov["files"].items()))
    atomic_write_text(side, json.dumps(prov, indent=1) + "\n")


def finish(t: Target, doc: Any, folder: Path = CLAIMS) -> None:
    """Write one results file and its stamp."""
    path = folder / t.name
    doc = json_safe(doc)
    if t.name != "certificate.json":       # certificate.py writes its own file
        atomic_write_text(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    stamp = make_stamp(doc, command=f"python benchmarks/regen_docs.py --files {t.name}",
                       inputs=t.inputs, root=ROOT, code_commit=_git_commit())
    write_stamp(folder, t.name, stamp)
    print(f"wrote {path.relative_to(ROOT)} (results {stamp['results_sha256'][:12]})",
          flush=True)


def _progress(name: str, f: Future[dict[str, Any]]) -> None:
    if f.exception() is None:
        r = f.result()
        print(f"  {name:24s} {r['controller']:8s} {r['label']:26s} "
              f"{'survived' if r['survived'] else 'LOST'}", flush=True)


def main(argv: list[str] | None = None) -> int:
    """Regenerate the chosen files (all but the certificate by default)."""
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ts = targets()
    ap.add_argument("--files", nargs="+", metavar="NAME",
                    help=f"results files to regenerate (default: all but certificate.json); "
                         f"one of {', '.join(ts)}")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes for the flights")
    ap.add_argument("--list", action="store_true", help="print the files and their runs")
    ap.add_argument("--stamp", nargs="*", metavar="FOLDER", default=None,
                    help="only stamp report folders copied in from vtolftc synth / campaign "
                         f"(default: all of {', '.join(REPORTS)})")
    ap.add_argument("--no-tables", action="store_true",
                    help="do not rewrite TABLES.md and rmse.png afterwards")
    a = ap.parse_args(argv)
    names = a.files or [n for n in ts if n != "certificate.json"]
    bad = [n for n in names if n not in ts]
    if bad:
        print(f"regen_docs: unknown results file {bad[0]!r}; expected one of {', '.join(ts)}",
              file=sys.stderr)
        return 2
    if a.jobs < 1:
        print(f"regen_docs: --jobs {a.jobs}: expected at least 1", file=sys.stderr)
        return 2
    if a.stamp is not None:
        folders = [f.rstrip("/") for f in a.stamp] or list(REPORTS)
        unknown = [f for f in folders if f not in REPORTS]
        if unknown:
            print(f"regen_docs: --stamp {unknown[0]!r}: expected one of {', '.join(REPORTS)}",
                  file=sys.stderr)
            return 2
        stamp_reports(folders)
        return 0
    chosen = [ts[n] for n in names]
    if a.list:
        for t in chosen:
            what = f"{len(t.jobs)} flights" if t.jobs else "computed"
            print(f"{t.name:24s} {what:12s} inputs: "
                  + ", ".join(p.relative_to(ROOT).as_posix() for p in t.inputs))
        return 0
    for t in chosen:                      # no flights: computed here, first
        if t.compute is not None:
            finish(t, t.compute())
    flown = [t for t in chosen if t.jobs]
    # table 4 flights first (40 s), then the rest in file order
    order = sorted(((t, i) for t in flown for i in range(len(t.jobs))),
                   key=lambda ti: (not ti[0].jobs[ti[1]][0].startswith("case"),))
    pos = {(t.name, i): k for k, (t, i) in enumerate(order)}
    with ProcessPoolExecutor(a.jobs) as ex:
        futs: dict[tuple[str, int], Future[dict[str, Any]]] = {}
        for t, i in order:
            f = ex.submit(fly, t.jobs[i])
            f.add_done_callback(lambda f, n=t.name: _progress(n, f))
            futs[(t.name, i)] = f
        # write each file as soon as its last flight is in
        for t in sorted(flown, key=lambda t: max(pos[(t.name, i)] for i in range(len(t.jobs)))):
            finish(t, [futs[(t.name, i)].result() for i in range(len(t.jobs))])
    if not a.no_tables:
        md = subprocess.run([sys.executable, str(CLAIMS / "tables.py")], check=True,
                            capture_output=True, text=True, cwd=ROOT).stdout
        atomic_write_text(CLAIMS / "TABLES.md", md)
        print("wrote docs/ds1-claims/TABLES.md, rmse.png", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
