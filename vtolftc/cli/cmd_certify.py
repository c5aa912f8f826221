"""``vtolftc certify``: an airframe file to a certified, fault-campaigned, SITL-flown GS-SHIF.

``vtolftc certify AIRFRAME.toml [--out DIR] [--jobs N] [--scheduler tcp://HOST:PORT]
[--resume] [--profile full|gates|quick]`` runs trim table -> robust synthesis -> mixed-mu
certificate -> envelope campaign (judged by the recoverability oracle) -> SITL mission over
UDP, writes ``DIR/report.html`` and exits 0 when every gate holds, 1 when one fails (the
report and stderr say which), 2 for bad input (one line), 130 on Ctrl-C / SIGTERM (finished
stages are kept: ``--resume`` reuses them, each cached by the airframe file's sha256, the
code and its upstream results).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import Any

from vtolftc.base.errors import UsageError


def _on_sigterm(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def run_certify(airframe: Path, out: Path, *, profile: str = "full", jobs: int | None = None,
                scheduler: str | None = None, resume: bool = False,
                stages: Sequence[Any] | None = None, code: str | None = None) -> int:
    """Run the pipeline (``stages`` default :func:`vtolftc.runners.certify.stages.default_stages`),
    write the report, print the gates; return 0 (every gate holds) or 1.

    Raises
    ------
    UsageError
        ``out`` holds another airframe's certify run, or a run without ``resume``.
    vtolftc.airframe.loader.AirframeError
        the airframe file is malformed or cannot fly.
    """
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.runners.certify.pipeline import StageContext, run_pipeline
    from vtolftc.runners.certify.report import write_report
    from vtolftc.runners.certify.stages import PROFILES, default_stages, sitl_command

    af = load_airframe(airframe)
    meta_path = out / "certify.json"
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a directory")
    if meta_path.is_file():
        try:
            meta = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            meta = {}
        if not resume:
            raise UsageError(f"--out {out}: already holds a certify run: pass --resume to "
                             "reuse its finished stages, or choose another --out")
        if meta.get("airframe_sha256") != af.sha256 or meta.get("profile") != profile:
            raise UsageError(f"--out {out}: holds the certify run of another airframe file or "
                             f"profile ({meta.get('airframe', '?')}, "
                             f"{meta.get('profile', '?')}); choose another --out")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--out {out}: cannot create the directory: {exc}") from None
    meta_path.write_text(json.dumps({"airframe": str(airframe), "airframe_sha256": af.sha256,
                                     "profile": profile}, indent=1) + "\n", encoding="utf-8")
    stages = list(stages) if stages is not None else default_stages()
    ctx = StageContext(airframe_path=Path(airframe), airframe_sha256=af.sha256, out_dir=out,
                       profile=PROFILES[profile], jobs=jobs, scheduler=scheduler,
                       resume=resume, log=lambda s: print(s, flush=True))
    old = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        res = run_pipeline(stages, ctx, code=code)
    except KeyboardInterrupt:
        print(f"interrupted: finished stages kept in {out}/stages; run again with --resume",
              file=sys.stderr)
        raise
    finally:
        signal.signal(signal.SIGTERM, old)
    gains = str(res.records.get("synth", {}).get("gains_dir", out / "synth"))
    again = ["vtolftc", "certify", str(airframe), "--out", str(out), "--profile", profile]
    import shlex

    commands = {s.name: shlex.join(again) for s in stages}
    commands["sitl"] = sitl_command(Path(airframe).resolve(), gains, out / "sitl-again")
    report = write_report(out / "report.html", airframe_name=af.name,
                          airframe_path=str(airframe), sha256=af.sha256, profile=profile,
                          records=res.records, titles={s.name: s.title for s in stages},
                          gate_failures=res.gate_failures, commands=commands)
    print(f"\ncertify {af.name}: " + ", ".join(
        f"{n} {r.get('verdict', '?')}" + (" (cached)" if n in res.cached else "")
        for n, r in res.records.items()))
    print(f"report: {report}")
    for r in res.records.values():
        for note in r.get("notes", []):
            print(f"note: {note}")
    for f in res.gate_failures:
        print(f"gate failed: {f}", file=sys.stderr)
    return 0 if res.passed else 1


def cmd_certify(args: argparse.Namespace) -> int:
    """Certify an airframe file (see ``vtolftc certify --help``)."""
    if args.jobs is not None and args.jobs < 1:
        raise UsageError(f"--jobs {args.jobs}: expected a number of processes >= 1")
    if args.scheduler is not None and args.jobs is not None:
        raise UsageError("--jobs and --scheduler: give one (the cluster sets its own workers)")
    if not Path(args.airframe).is_file():
        raise UsageError(f"{args.airframe}: no such airframe file (give an airframe TOML file "
                         "such as airframe/ds1.toml)")
    out = Path(args.out) if args.out else Path("runs") / f"certify-{Path(args.airframe).stem}"
    return run_certify(Path(args.airframe), out, profile=args.profile, jobs=args.jobs,
                       scheduler=args.scheduler, resume=args.resume)


def register(sub: Any) -> None:
    """Add the ``certify`` subcommand to the CLI's subparsers."""
    p = sub.add_parser("certify", help="trim, robust synthesis, mu certificate, fault campaign "
                       "and SITL mission of an airframe file, one report with gates",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("airframe", type=Path, help="airframe TOML file (e.g. airframe/ds1.toml)")
    p.add_argument("--out", default=None, help="output folder (default runs/certify-NAME)")
    p.add_argument("--jobs", type=int, default=None,
                   help="local processes for the campaign (default: all cores; the synthesis "
                        "uses at most 2)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="fly the campaign on the Dask scheduler at ADDRESS (tcp://HOST:PORT)")
    p.add_argument("--resume", action="store_true",
                   help="reuse the finished stages in --out (same airframe file and code)")
    p.add_argument("--profile", choices=("full", "gates", "quick"), default="full",
                   help="full (default): the certification; gates: the full synthesis and "
                        "the campaign's gated families only (single and double lift rotors "
                        "off, hover and mid-transition, calm); quick: a slice for tests")
    p.set_defaults(func=cmd_certify)
