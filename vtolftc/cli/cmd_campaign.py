"""``vtolftc campaign``: fly a fault campaign (spec file) in parallel and report it.

``vtolftc campaign SPEC.toml [--out DIR] [--jobs N] [--scheduler tcp://HOST:PORT] [--resume]``
prints the scenario count, flies the scenarios on a local process pool (default: all cores)
or on a Dask cluster, appends results to ``DIR/parts/`` as they finish (with a progress bar),
then writes ``results.parquet``, ``report.html`` with its PNGs, prints the survival summary and
the worst scenarios, and checks the spec's gates (exit status 1 when one fails).
``vtolftc campaign --compare A B`` prints what changed between two result files or folders.
Bad specs and options are one line with exit status 2; SIGTERM and Ctrl-C stop after writing
what finished (exit 130); ``--resume`` flies only the missing scenarios.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path
from types import FrameType
from typing import Any

from vtolftc.base.errors import UsageError
from vtolftc.base.jsonio import atomic_write_text, dumps


def _usage(msg: str) -> Exception:

    return UsageError(msg)


def _on_sigterm(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def cmd_campaign(args: argparse.Namespace) -> int:
    """Fly a fault campaign from a spec file (see ``vtolftc campaign --help``)."""
    if args.compare:
        return _compare(args.compare)
    if args.spec is None:
        raise _usage("a spec file is needed: vtolftc campaign SPEC.toml (or --compare A B)")
    if args.batch < 1:
        raise _usage(f"--batch {args.batch}: expected a number of rows per part >= 1")
    if args.jobs is not None and args.jobs < 1:
        raise _usage(f"--jobs {args.jobs}: expected a number of processes >= 1")
    if args.scheduler is not None and args.jobs is not None:
        raise _usage("--jobs and --scheduler: give one (the cluster sets its own workers)")
    from vtolftc.runners.campaign.results import PartWriter, read_results, write_final
    from vtolftc.runners.campaign.scenarios import expand, flight_order
    from vtolftc.runners.campaign.spec import SpecError, load_spec

    try:
        spec = load_spec(args.spec)
        scenarios = expand(spec)
    except SpecError as exc:
        raise _usage(str(exc)) from None
    out = Path(args.out) if args.out else Path("runs") / f"campaign-{spec.name}"
    meta_path = out / "campaign.json"
    if meta_path.is_file():
        try:
            meta = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            meta = {}
        if meta.get("spec_sha256") != spec.sha256:
            raise _usage(f"--out {out}: holds results of another spec "
                         f"({meta.get('spec', '?')}); choose another --out")
    done = read_results(out) if out.exists() else None
    n_done = 0 if done is None else done.num_rows
    if args.report_only:
        if not n_done:
            raise _usage(f"--report-only: no results in {out}")
        print(f"campaign {spec.name}: report of the {n_done} of {len(scenarios)} scenarios "
              f"flown in {out}")
        return _finish(spec, write_final(out), out, 0.0, 0, len(scenarios))
    if n_done and not args.resume:
        raise _usage(f"--out {out}: already holds {n_done} results: pass --resume to fly only "
                     "the missing scenarios, or choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(meta_path, dumps({
        "spec": spec.source, "spec_name": spec.name, "spec_sha256": spec.sha256,
        "scenarios": len(scenarios)}))
    (out / "spec.toml").write_text(spec.text, encoding="utf-8")
    done_ids = set() if done is None else set(done.column("scenario_id").to_pylist())
    todo = flight_order([s for s in scenarios if s.scenario_id not in done_ids],
                        len(spec.controllers))
    n_surv = 0 if done is None else sum(done.column("survived").to_pylist())
    where = (f"Dask scheduler {args.scheduler}" if args.scheduler else
             f"{args.jobs or _cpus()} local processes")
    print(f"campaign {spec.name}: {len(scenarios)} scenarios"
          + (f" ({n_done} already done, {len(todo)} to fly)" if n_done else "")
          + f" on {where} -> {out}", flush=True)

    old = signal.signal(signal.SIGTERM, _on_sigterm)
    writer = PartWriter(out, batch=args.batch)
    t0 = time.perf_counter()
    client = None
    try:
        if todo:
            client = _dask_client(args.scheduler, todo) if args.scheduler else None
            oracle = _oracle(todo)
            _fly(args, spec, todo, writer, len(scenarios), n_done, n_surv, oracle, client)
    except KeyboardInterrupt:
        writer.close()
        print(f"interrupted: {writer.written} new results written to {out}/parts; "
              "run again with --resume to fly the rest", file=sys.stderr)
        raise
    finally:
        writer.close()
        if client is not None:  # e.g. Ctrl-C during the oracle: the workers' plugins off
            from vtolftc.runners.campaign.dask_run import release_workers

            release_workers(client)
            client.close()
        signal.signal(signal.SIGTERM, old)
    wall = time.perf_counter() - t0
    table = write_final(out)
    return _finish(spec, table, out, wall, len(todo), len(scenarios))


def _cpus() -> int:
    import os

    return os.cpu_count() or 1


def _dask_client(address: str, todo: list[Any]) -> Any:
    """A client of the Dask scheduler at ``address`` whose workers start warming for
    ``todo`` at once (while this process computes the oracle); bad address: usage error."""
    from vtolftc.runners.campaign.dask_run import connect
    from vtolftc.runners.campaign.execute import prepare_dask

    try:
        client = connect(address)
    except ConnectionError as exc:
        raise _usage(str(exc)) from None
    prepare_dask(client, todo)
    return client


def _oracle(todo: list[Any]) -> dict[str, dict[str, Any]]:
    """The physical oracle's columns of the scenarios to fly (one reference flight + LPs)."""
    from vtolftc.runners.campaign.oracle import oracle_columns

    t0 = time.perf_counter()
    try:
        cols = oracle_columns(todo)
    except Exception as exc:  # never lose a campaign to its judge: the rows say "not judged"
        print(f"recoverability oracle: not judged ({type(exc).__name__}: {exc})", flush=True)
        return {}
    n_rec = sum(c["recoverable"] for c in cols.values())
    print(f"recoverability oracle: {n_rec} of {len(cols)} scenarios recoverable "
          f"({time.perf_counter() - t0:.1f} s)", flush=True)
    return cols


def _fly(args: argparse.Namespace, spec: Any, todo: list[Any], writer: Any, total: int,
         n_done: int, n_surv: int, oracle: dict[str, dict[str, Any]] | None = None,
         client: Any = None) -> None:
    from tqdm import tqdm

    from vtolftc.runners.campaign.execute import run_dask, run_local

    if client is not None:
        stream: Any = run_dask(todo, client, tag=spec.sha256[:8])
    else:
        stream = run_local(todo, args.jobs)
    survived, flown = n_surv, n_done

    class _Bar(tqdm):  # type: ignore[misc]
        monitor_interval = 0  # no monitor thread: the local pool forks only a lone thread

    bar = _Bar(total=total, initial=n_done, unit="scen", dynamic_ncols=True,
               desc=spec.name, disable=args.no_progress, file=sys.stderr)
    try:
        for row in stream:
            row.update((oracle or {}).get(row["scenario_id"], {}))
            writer.add(row)
            flown += 1
            survived += bool(row["survived"])
            bar.set_postfix_str(f"survived {survived}/{flown}", refresh=False)
            bar.update(1)
    finally:
        close = getattr(stream, "close", None)
        if close is not None:
            close()
        bar.close()


def _finish(spec: Any, table: Any, out: Path, wall: float, n_flown: int, total: int) -> int:
    from vtolftc.runners.campaign.execute import cached_airframe
    from vtolftc.runners.campaign.report import (
        check_gates,
        recoverable_lines,
        summary_lines,
        worst,
        write_report,
    )

    rows = table.num_rows
    surv = sum(table.column("survived").to_pylist())
    rate = f", {60.0 * n_flown / wall:.1f} scenarios/min" if n_flown and wall > 0 else ""
    partial = f" (partial: {rows} of {total} scenarios flown)" if rows < total else ""
    print(f"\n{spec.name}: survived {surv}/{rows}{partial}; flew {n_flown} in {wall:.1f} s{rate}")
    print()
    for line in summary_lines(table):
        print(line)
    rec = recoverable_lines(table)
    if rec:
        print("\nsurvived / recoverable (the physical oracle) per family and phase:")
        for line in rec:
            print(line)
    failures = check_gates(spec.gates, table)
    report = write_report(out, table, title=f"Campaign {spec.name}",
                          description=spec.description + partial,
                          airframe=cached_airframe(spec.airframe_path),
                          gate_failures=failures)
    print("\nworst scenarios (re-fly with the command shown):")
    for r in worst(table, 5):
        if r["survived"]:
            break
        when = (f"crash at {r['crash_time_s']:.2f} s" if r["crashed"] and r["outcome"] != "error"
                else r["outcome"])
        print(f"  {r['controller']} {r['faults']} @ {r['phase']} (wind {r['wind']}): {when}")
        print(f"    {r['fly_command']}")
    print(f"\nresults: {out / 'results.parquet'}; report: {report}")
    if failures:
        for f in failures:
            print(f, file=sys.stderr)
        return 1
    return 0


def _compare(paths: list[str]) -> int:
    from vtolftc.runners.campaign.report import compare
    from vtolftc.runners.campaign.results import read_results

    tables = []
    for p in paths:
        if not Path(p).exists():
            raise _usage(f"--compare {p}: no such result file or campaign folder")
        try:
            tables.append(read_results(p))
        except Exception as exc:  # pyarrow raises several types for a non-Parquet file
            raise _usage(f"--compare {p}: not a campaign result file ({exc})") from None
    for line in compare(tables[0], tables[1], paths[0], paths[1]):
        print(line)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``campaign`` subcommand to the CLI's subparsers."""
    p = sub.add_parser("campaign", help="fly a fault campaign (spec file) on local cores or a "
                       "Dask cluster and report where each controller survives",
                       description=__doc__.split("\n\n")[1] if __doc__ else None)
    p.add_argument("spec", nargs="?", type=Path, default=None, help="campaign spec (TOML)")
    p.add_argument("--out", default=None, help="output folder (default runs/campaign-NAME)")
    p.add_argument("--jobs", type=int, default=None,
                   help="local processes (default: all cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on the Dask scheduler at ADDRESS (tcp://HOST:PORT); start its "
                        "workers warm with `dask worker ADDRESS --nthreads 1 --preload "
                        "vtolftc.runners.campaign.dask_preload`")
    p.add_argument("--resume", action="store_true",
                   help="continue a campaign in --out: fly only the missing scenarios")
    p.add_argument("--compare", nargs=2, metavar=("A", "B"), default=None,
                   help="print what changed between two result files or folders")
    p.add_argument("--report-only", action="store_true",
                   help="fly nothing: summary, gates and report of the results in --out")
    p.add_argument("--batch", type=int, default=8,
                   help="results per Parquet part (written at least every 10 s; default 8)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_campaign)
