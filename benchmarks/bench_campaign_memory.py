"""Resident memory of a long campaign on the local pool and on Dask clusters (issue 24).

Flies N short scenarios (``--duration`` s each, default 2: the growth is per scenario flown,
not per simulated second, so short flights reach 2000 scenarios in minutes; the rotor losses
at N / 24 magnitudes, the three controllers) with the parent writing Parquet parts as
``vtolftc campaign`` does, on each backend in turn, in one run:

- ``pool``: the local process pool (workers forked from the parent, each replaced after
  ``WORKER_SCENARIOS``);
- ``LocalCluster``: a fresh Dask ``LocalCluster`` started here (N workers, one thread each,
  loopback; its scheduler and nannies run in this process, the workers are its children);
- ``tcp``: a fresh ``tcp://127.0.0.1:PORT`` cluster, a ``dask scheduler`` and a ``dask worker
  --nworkers N --nthreads 1`` process (its nannies; the workers its children) started here
  and stopped by pid at the end.

The resident set (``VmRSS``) of every process of the campaign, by pid (client / parent,
scheduler, nannies, workers: :func:`vtolftc.runners.campaign.dask_run.cluster_pids`), is
sampled against the number of rows received (about 500 samples, never against the wall
clock), and each process's Theil-Sen slope after the first quarter is printed as MB per 2000
scenarios (issue 24's target: < 50 MB for the parent and each worker), with its RSS at the
first and last sample. After a Dask campaign, what Dask itself holds is printed
(:func:`~vtolftc.runners.campaign.dask_run.cluster_holdings`: results kept on the workers,
tasks known to workers and scheduler, the length of their logs). ``--trace`` also starts
``tracemalloc`` in each Dask worker after the first quarter and prints, at the end, the
Python memory traced there and the allocation sites that grew most.

Measured 2026-12-02 16:41-16:45 UTC (load 18 falling to 13 on 2 shared cores; docs/campaigns/
README.md, "Memory of a Dask campaign"), 2000 scenarios of 2 s, 2 workers, slopes per 2000:

- fresh LocalCluster (2000 in 80 s): client + scheduler + nannies +0.02 MB; workers +10.0 and
  +11.2 MB (RSS ~68 -> 211-212 MB, the imports and kernels before the first row included);
- fresh tcp:// cluster (2000 in 138 s): client +0.00 MB, scheduler +0.03 MB, the nannies'
  process +0.00 MB, workers +9.9 and +10.3 MB (~67 -> 211 MB);
- Dask's holdings after each: 0 results and 0 tasks on the workers, 0 tasks, 0 task groups
  and 1 prefix on the scheduler, logs bounded (~300 and ~400 entries of 1000);
- ``--trace`` (16:20-16:40, load 17-25): the workers' Python heap from scenario 500 to 2000
  +0.76-0.77 MB after ``gc.collect()`` (Dask's system monitor, bounded), 1.2-10 MB before
  it (cyclic garbage of finished flights); its RSS slopes (+30-31 MB) include tracemalloc's
  own records and are not the campaign's.

The workers' ~10 MB is their allocators settling over their first ~850 flights (+2.2, +2.0,
+1.9, +1.7, +1.9, +0.6, +0.0 MB in blocks of ~330 campaign scenarios, an earlier run): under
the 50 MB target, so Dask workers are not restarted at a flight count.

    python benchmarks/bench_campaign_memory.py [--scenarios 2000] [--duration 2] [--jobs 2]
        [--backends pool,LocalCluster,tcp] [--trace]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

HERE = os.path.dirname(os.path.abspath(__file__))
MB = 2.0 ** 20
PER = 2000
"""Campaign length the slopes are quoted for (scenarios)."""


def memory_spec(n: int, duration_s: float) -> str:
    """A spec of at least ``n`` short scenarios: each lift rotor's loss at ceil(n / 24)
    magnitudes, the three controllers, injected at half the duration (s)."""
    k = max(1, -(-n // 24))
    mags = ", ".join(f"{0.02 + 0.6 * i / k:.5f}" for i in range(k))
    return (f'[campaign]\nname = "memory"\nduration_s = {duration_s:g}\n'
            f'controllers = ["gs-shif", "shif", "lqr"]\nphases = [{duration_s / 2:g}]\n'
            '[[faults]]\nfamily = "rotor-loss"\ngenerate = "each"\n'
            f'actuators = ["lift_rotors"]\nkinds = ["loss"]\nmagnitudes = [{mags}]\n')


def fly_sampled(rows: Iterable[dict[str, Any]], n: int,
                sample: Callable[[int], None]) -> tuple[float, int]:
    """Consume ``rows`` (``n`` expected) into Parquet parts, calling ``sample(done)`` about
    500 times; returns (wall s, rows)."""
    from vtolftc.runners.campaign.results import PartWriter

    every = max(1, n // 500)
    t = time.perf_counter()
    done = 0
    with tempfile.TemporaryDirectory() as d:
        w = PartWriter(Path(d))
        sample(0)
        for r in rows:
            w.add(r)
            done += 1
            if done % every == 0 or done == n:
                sample(done)
        w.close()
    return time.perf_counter() - t, done


def print_slopes(watch: Any, n: int, pids: Iterable[int] | None = None) -> None:
    """Each process's RSS first -> last and its slope after the first quarter (MB per
    :data:`PER` scenarios)."""
    g = watch.growth(PER)
    for pid in pids if pids is not None else sorted(g):
        if pid not in g:
            continue
        x = g[pid]
        print(f"  {watch.label(pid)}: RSS {x['rss_first_b'] / MB:.1f} -> "
              f"{x['rss_last_b'] / MB:.1f} MB; slope after the first quarter "
              f"{x['slope_b_per_scenario'] / 1024:+.2f} KB per scenario -> "
              f"{x['growth_b'] / MB:+.2f} MB per {PER} (target < 50 MB)")


def pool_run(scen: list[Any], jobs: int) -> float:
    """The local pool: parent's slope, workers' growth in their lives and the slope of the
    largest worker's RSS. Returns the rate (scenarios/min)."""
    from vtolftc.runners.campaign.execute import WORKER_SCENARIOS, run_local
    from vtolftc.runners.campaign.memwatch import RssWatch, robust_slope

    watch = RssWatch()
    wall, done = fly_sampled(run_local(scen, jobs), len(scen), watch.sample)
    rate = 60.0 * done / wall
    print(f"pool ({jobs} processes): {done} scenarios in {wall:.1f} s = {rate:.1f} "
          f"scenarios/min; load {os.getloadavg()[0]:.2f}")
    print_slopes(watch, done, [watch.parent])
    workers = {p: s for p, s in watch.samples.items() if p != watch.parent and len(s) >= 2}
    life = [s[-1][1] - s[0][1] for s in workers.values()]
    largest: dict[int, int] = {}
    for s in workers.values():
        for k, rss in s:
            largest[k] = max(largest.get(k, 0), rss)
    ks = sorted(k for k in largest if k >= done // 4)
    wslope = robust_slope(ks, [largest[k] for k in ks])
    print(f"  workers: {len(workers)} processes in all (each replaced after "
          f"{WORKER_SCENARIOS} scenarios); RSS "
          f"{min(s[0][1] for s in workers.values()) / MB:.1f}-{max(largest.values()) / MB:.1f}"
          f" MB; largest growth in a worker's life {max(life) / MB:+.1f} MB; slope of the "
          f"largest worker's RSS {wslope * PER / MB:+.2f} MB per {PER} (target < 50 MB)")
    return rate


def _trace_start(dask_worker: Any) -> int:
    """Start tracemalloc on a worker (run there); its traced bytes now."""
    import tracemalloc

    tracemalloc.start(1)
    dask_worker._vtolftc_trace0 = tracemalloc.take_snapshot()
    return tracemalloc.get_traced_memory()[0]


def _trace_report(dask_worker: Any) -> list[str]:
    """The worker's traced bytes and the sites that grew most since :func:`_trace_start`."""
    import gc
    import tracemalloc

    traced = tracemalloc.get_traced_memory()[0]
    enabled, counts, thresholds = gc.isenabled(), gc.get_count(), gc.get_threshold()
    freed = gc.collect()
    snap = tracemalloc.take_snapshot()
    diff = snap.compare_to(dask_worker._vtolftc_trace0, "lineno")
    after = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    out = [f"traced {traced / MB:.2f} MB; gc enabled {enabled}, counts {counts}, thresholds "
           f"{thresholds}; gc.collect() freed {freed} objects -> traced {after / MB:.2f} MB; "
           "grown most"]
    out += [f"{d.size_diff / 1024:+.1f} KB ({d.count_diff:+d} blocks) "
            f"{d.traceback[0].filename.rsplit('site-packages/', 1)[-1]}:{d.traceback[0].lineno}"
            for d in diff[:6]]
    return out


def dask_run(kind: str, scen: list[Any], jobs: int, trace: bool) -> float:
    """A fresh ``kind`` cluster's campaign: every process's slope and Dask's holdings.
    Returns the rate (scenarios/min)."""
    from bench_campaign import fresh_cluster

    from vtolftc.runners.campaign.dask_run import cluster_holdings, cluster_pids, connect
    from vtolftc.runners.campaign.execute import prepare_dask, run_dask
    from vtolftc.runners.campaign.memwatch import RssWatch, rss_bytes

    with fresh_cluster(kind, jobs) as address:
        client = connect(address)
        try:
            client.wait_for_workers(jobs, timeout=300)
            roles = cluster_pids(client)
            watch = RssWatch()
            watch.labels.update(roles)
            watch.labels[watch.parent] = "+".join(
                ["client", *([roles[watch.parent]] if watch.parent in roles else [])])
            n = len(scen)
            traced: dict[str, int] = {}

            def sample(done: int) -> None:
                if any(rss_bytes(p) is None for p in roles):  # a worker restarted
                    roles.clear()
                    roles.update(cluster_pids(client))
                    watch.labels.update(roles)
                if trace and not traced and done >= n // 4:
                    traced.update(client.run(_trace_start))
                watch.sample(done, roles)

            prepare_dask(client, scen)
            wall, done = fly_sampled(run_dask(scen, client, tag="memory"), n, sample)
            held = cluster_holdings(client)
            reports = client.run(_trace_report) if trace else {}
        finally:
            client.close()
    rate = 60.0 * done / wall
    print(f"Dask {kind} ({jobs} workers, fresh): {done} scenarios in {wall:.1f} s = "
          f"{rate:.1f} scenarios/min; load {os.getloadavg()[0]:.2f}")
    print_slopes(watch, done)
    print(f"  held by Dask after the campaign: {held}")
    for addr, lines in reports.items():
        print(f"  tracemalloc, worker {addr} (traced from scenario {n // 4}): " + "; ".join(lines))
    return rate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", type=int, default=PER)
    ap.add_argument("--duration", type=float, default=2.0, help="s per scenario")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--backends", default="pool,LocalCluster,tcp")
    ap.add_argument("--trace", action="store_true", help="tracemalloc in the Dask workers")
    args = ap.parse_args()
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    bad = sorted(set(backends) - {"pool", "LocalCluster", "tcp"})
    if bad or args.scenarios < 8 or args.duration <= 0 or args.jobs < 1:
        print(f"bench_campaign_memory: bad arguments (backends {bad or backends}, scenarios "
              f">= 8, duration > 0, jobs >= 1)", file=sys.stderr)
        sys.exit(2)
    sys.path.insert(0, HERE)

    from vtolftc.runners.campaign.scenarios import expand
    from vtolftc.runners.campaign.spec import parse_spec

    scen = expand(parse_spec(memory_spec(args.scenarios, args.duration)))[: args.scenarios]
    print(f"load average at start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"{len(scen)} scenarios of {args.duration:g} s, {args.jobs} workers; "
          f"{time.strftime('%H:%M:%S', time.gmtime())} UTC")
    rates = {}
    for b in backends:
        rates[b] = (pool_run(scen, args.jobs) if b == "pool"
                    else dask_run(b, scen, args.jobs, args.trace))
    if "pool" in rates:
        for b, r in rates.items():
            if b != "pool":
                print(f"rate of these short flights, Dask {b} / pool: {r / rates['pool']:.2f}x")
    print(f"load average at end: {os.getloadavg()[0]:.2f}; "
          f"{time.strftime('%H:%M:%S', time.gmtime())} UTC")


if __name__ == "__main__":
    main()
