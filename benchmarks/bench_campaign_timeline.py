"""Per-worker timelines of a campaign on the local pool and on fresh Dask clusters, and the
CPU of every process: where a Dask campaign loses against the pool (issue 24, session 18).

Flies ``bench_campaign.py``'s scenarios (60 s flights, a 10 % loss of one lift rotor in
cruise) as ``vtolftc campaign`` does: on the local pool (forked from this warm process), and
on a fresh cluster of each ``--kinds`` (``LocalCluster`` in this process; ``tcp``: ``dask
scheduler`` + ``dask worker`` processes), the client first registering the campaign's
plugins, then computing the oracle while the workers warm, then the flights
(``run_dask``), then a second campaign on the same cluster. Each flight is wrapped to
report its process, its start and end on the wall clock, the CPU time of its own thread
and of its process's other threads, its minor page faults and context switches. Printed
per campaign:

- per worker: flights, when its first starts and its last ends (relative to the start of
  the flights), its idle time at the end while the other worker still flies (the tail),
  the gaps between its flights (dispatch: the result back, the next task out), the mean
  flight's wall and thread CPU time, its other threads' CPU during its flights;
- the rows' arrival lag in the parent (end of flight to the row in the parent's hands);
- the CPU of every process of the campaign over the flights (parent: client, and in a
  ``LocalCluster`` the scheduler and nannies; the scheduler, nanny and worker processes)
  per scenario, against the machine's busy CPU over the same window (the rest is other
  processes: the neighbours of a shared machine).

The CPU figures are load-robust; the wall times are not (a neighbour's burst moves a
flight's wall time 2x without changing its thread CPU).

Session 18 (2026-12-03, branch dask-18, 18:27-18:47 UTC, load 2-4.5 from other helpers'
jobs; the neighbours took 0-20 s of CPU in a 5-15 s window, so no wall-time ratio here
holds):

- the tail is not where Dask loses: the scheduler's queuing (``worker-saturation`` 1.1, one
  thread per worker) already hands out the 24 one-scenario tasks as workers free, like the
  pool's shared queue: 12/12 flights per worker in 8 of 10 fresh and second campaigns,
  13/11 twice (a late-warmed worker), the early worker idle 0.02-0.41 s at the end against
  0.01-0.86 s in the pool. A submission window or longest-first order has nothing to take.
- dispatch is not either: gaps between a worker's flights 1.4-7.1 ms median (pool 0.3-5.6
  ms), 0.02-0.10 s per 12 flights (< 1 %); rows reach the parent 15-35 ms after their
  flight (pool 3-4 ms), off the workers' path.
- a fresh worker's start: its first flight started 0.03-1.43 s after the flights began
  (the oracle, 0.7-3.2 s at this load, hides only part of two workers' warm-up on 2 cores).
  In CPU: a fresh interpreter imports ``distributed`` (0.32-0.36 s, before it registers),
  then the flight code (0.54 s: numba, the kernels' cache loads at import, scipy.linalg),
  then ``warm_up`` (0.12 s for the three controllers); its first 60 s flight then costs
  +0.01 s over the next. The fresh campaign's workers took 10.8-11.2 s of CPU for 24
  flights against 9.1-9.8 s in the second campaign: ~0.7 s per worker, ~2 flights each,
  14-18 % of this campaign's flights, which the local pool never pays (its workers fork
  from the warm parent).
- the steady state: CPU per scenario of every process, second campaign (warm), 0.39-0.43 s
  against the pool's 0.37-0.41 s. Besides the flights, a 24-scenario campaign took the
  ``LocalCluster`` parent (client + scheduler + nannies) 0.24-0.42 s and a ``tcp://``
  scheduler 0.19-0.31 s, most of it the scheduler's background (its 20 ms tick, its system
  monitor: idle, scheduler + 2 nannies 1.6-2.2 % of a core, each worker 0.75-1.0 %); the
  workers' other threads 0.06-0.20 s per 12 flights. A flight's thread CPU in a worker
  (0.37-0.41 s) is the pool's (0.37-0.39 s) within this load's spread, and a flight with
  the collector frozen or off costs the same (one gen-0 collection per flight, 0.1 ms).
- the build (``dask_plugin.QuietScheduler``, the workers' system monitor paused and their
  memory check every 1 s): an idle ``LocalCluster`` of 2 with the campaign's plugins, main
  then branch, 2 interleaved pairs (load 1.3-2.9): scheduler + nannies + client 1.5-2.25 %
  -> 0.75-0.87 % of a core, the two workers 1.62-2.0 % -> 0.75-0.87 %. Per 24-scenario
  campaign, main then branch interleaved (3 pairs ``LocalCluster``, 2 pairs ``tcp://``,
  load 1.8-4.7): the ``LocalCluster`` parent 0.24 / 0.37 / 0.42 s -> 0.18 / 0.22 / 0.27 s
  (second campaigns), the ``tcp://`` scheduler 0.19-0.31 s -> 0.12-0.17 s; ~0.1 s of ~9.5
  s, ~1 % of the campaign's CPU. The flights' own spread (+-3 % at this load) hides it in
  the totals.

One run of this benchmark on the branch (19:00 UTC, load 1.5 rising to 2.7, neighbours
taking 3-10 s of CPU per window): pool 0.403 s of CPU per scenario (parent 0.12 s in all),
workers 12/12, idle at the end 0.01-0.06 s, gaps 0.3-0.5 ms; fresh ``LocalCluster``
(oracle 1.31 s) 0.430 s, flights 11/13, first flights +0.20 / +0.35 s, idle at the end 0.26
s, gaps 4.3-4.6 ms, parent 0.21 s, workers 10.11 s; its second campaign 0.406 s (13/11,
idle 0.31 s at the end, workers 9.55 s); fresh ``tcp://`` (oracle 1.43 s) 0.433 s, 12/12,
first flights +0.47 / +0.53 s, scheduler 0.17 s, workers 10.12 s; second 0.406 s
(scheduler 0.13 s, workers 9.50 s). Flight thread CPU medians 0.387-0.400 s everywhere
(pool 0.398 s). The fresh clusters' workers took ~0.6 s more CPU than on their second
campaign, the rest of their warm-up having run during the oracle.

    python benchmarks/bench_campaign_timeline.py [--scenarios 24] [--kinds pool,LocalCluster,tcp]
"""

from __future__ import annotations

import argparse
import itertools
import os
import resource
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

HERE = os.path.dirname(os.path.abspath(__file__))


def timed_fly(sc: Any) -> dict[str, Any]:
    """:func:`~vtolftc.runners.campaign.execute.fly_scenario`'s row with the flight's pid,
    wall-clock span, thread and process CPU, minor faults and context switches (``_*``)."""
    import vtolftc.runners.campaign.execute as ex

    fly = getattr(ex, "_bench_fly", ex.fly_scenario)
    r0 = resource.getrusage(resource.RUSAGE_THREAD)
    t0, c0, p0 = time.time(), time.thread_time(), time.process_time()
    row = fly(sc)
    r1 = resource.getrusage(resource.RUSAGE_THREAD)
    row.update(_pid=os.getpid(), _t0=t0, _t1=time.time(), _tcpu=time.thread_time() - c0,
               _pcpu=time.process_time() - p0, _minflt=r1.ru_minflt - r0.ru_minflt,
               _nivcsw=r1.ru_nivcsw - r0.ru_nivcsw, _threads=threading.active_count())
    return row


def timed_batch(batch: list[Any]) -> list[dict[str, Any]]:
    """A Dask task: :func:`timed_fly` of each scenario."""
    return [timed_fly(sc) for sc in batch]


def machine_busy_s() -> float:
    """Busy CPU seconds of the whole machine since boot (``/proc/stat``)."""
    with open("/proc/stat", encoding="ascii") as fh:
        f = [int(x) for x in fh.readline().split()[1:]]
    return (sum(f) - f[3] - f[4]) / os.sysconf("SC_CLK_TCK")


def process_cpu(pids: dict[int, str]) -> dict[str, float]:
    """CPU seconds per role of the processes ``pids`` (this one by :func:`os.times`, its
    children it has waited for, e.g. the pool's workers once it ends, as ``workers``)."""
    from bench_campaign import proc_stat

    t = os.times()
    out: dict[str, float] = {"workers": t.children_user + t.children_system}
    for pid, role in pids.items():
        if pid == os.getpid():
            cpu = t.user + t.system
        else:
            st = proc_stat(pid)
            cpu = st[1] if st is not None else 0.0
        out[role] = out.get(role, 0.0) + cpu
    return out


def campaign(stream: Any, pids: dict[int, str]) -> tuple[list[dict[str, Any]], list[float], float,
                                                float, dict[str, float], float]:
    """Consume ``stream`` as the CLI does (rows to Parquet parts); returns the rows, their
    arrival times, the start and end, the CPU per role of ``pids`` over it and the
    machine's busy CPU over it."""
    from vtolftc.runners.campaign.results import PartWriter

    rows, arrived = [], []
    with tempfile.TemporaryDirectory() as d:
        w = PartWriter(Path(d))
        t0 = time.time()
        c0, b0 = process_cpu(pids), machine_busy_s()
        for r in stream:
            arrived.append(time.time())
            w.add({k: v for k, v in r.items() if not k.startswith("_")})
            rows.append(r)
        w.close()
        t1 = time.time()
        c1, b1 = process_cpu(pids), machine_busy_s()
    return rows, arrived, t0, t1, {k: c1[k] - c0.get(k, 0.0) for k in c1}, b1 - b0


def summarize(label: str, got: tuple[Any, ...]) -> None:
    """Print the per-worker timeline and the CPU per role of one campaign."""
    rows, arrived, t0, t1, cpu, busy = got
    n = len(rows)
    print(f"== {label}: {n} flights in {t1 - t0:.2f} s ({60 * n / (t1 - t0):.1f}/min); load "
          f"{os.getloadavg()[0]:.2f}")
    by: dict[int, list[dict[str, Any]]] = {}
    for r in rows:
        by.setdefault(r["_pid"], []).append(r)
    for pid, rs in sorted(by.items()):
        rs.sort(key=lambda r: r["_t0"])
        gaps = [b["_t0"] - a["_t1"] for a, b in itertools.pairwise(rs)]
        print(f"  worker {pid}: {len(rs)} flights, first starts +{rs[0]['_t0'] - t0:.2f} s, "
              f"last ends +{rs[-1]['_t1'] - t0:.2f} s, idle at the end {t1 - rs[-1]['_t1']:.2f}"
              f" s; gaps median {1e3 * statistics.median(gaps) if gaps else 0.0:.1f} ms, sum "
              f"{sum(gaps):.2f} s; flight wall "
              f"{statistics.mean(r['run_wall_time_s'] for r in rs):.3f} s, thread CPU "
              f"{statistics.mean(r['_tcpu'] for r in rs):.3f} s; other threads "
              f"{sum(r['_pcpu'] - r['_tcpu'] for r in rs):.2f} s; minor faults "
              f"{statistics.mean(r['_minflt'] for r in rs):.0f}, preemptions "
              f"{statistics.mean(r['_nivcsw'] for r in rs):.0f} per flight")
    lag = [a - r["_t1"] for a, r in zip(arrived, rows, strict=True)]
    ours = sum(cpu.values())
    print(f"  rows reach the parent {1e3 * statistics.median(lag):.1f} ms after their flight "
          f"(median; max {1e3 * max(lag):.1f}); thread CPU median "
          f"{statistics.median(r['_tcpu'] for r in rows):.4f} s per flight")
    print(f"  CPU over the flights: {ours / n:.4f} s per scenario (" + ", ".join(
        f"{k} {v:.2f} s" for k, v in sorted(cpu.items())) + f"); the machine {busy:.2f} s of "
        f"{2 * (t1 - t0):.2f}, others {busy - ours:.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", type=int, default=24,
                    help="24 per loss magnitude (10 %%, 20 %%, ... 100 %%): at most 240")
    ap.add_argument("--kinds", default="pool,LocalCluster,tcp")
    args = ap.parse_args()
    if not 1 <= args.scenarios <= 240:
        ap.error("--scenarios: give 1 to 240 (24 per loss magnitude, 10 % to 100 %)")
    sys.path.insert(0, HERE)
    from bench_campaign import fresh_cluster, spec_of

    import vtolftc.runners.campaign.execute as ex
    from vtolftc.runners.campaign.dask_run import cluster_pids, connect
    from vtolftc.runners.campaign.oracle import oracle_columns
    from vtolftc.runners.campaign.scenarios import expand
    from vtolftc.runners.campaign.spec import parse_spec

    scen = expand(parse_spec(spec_of(args.scenarios)))[: args.scenarios]
    print(f"load average at start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"{len(scen)} scenarios of 60 s, 2 workers")
    ex.fly_scenario(scen[0])  # this process warm, as the campaign's is after its oracle
    oracle_columns(scen)
    ex._bench_fly, fly, batch = ex.fly_scenario, ex.fly_scenario, ex.fly_batch
    for kind in args.kinds.split(","):
        if kind == "pool":
            ex.fly_scenario = timed_fly  # the forked workers call it
            try:
                summarize("local pool (forked from this process)", campaign(
                    ex.run_local(scen, 2), {os.getpid(): "parent"}))
            finally:
                ex.fly_scenario = fly
            continue
        ex.fly_batch = timed_batch  # pickled by value (this is __main__)
        try:
            with fresh_cluster(kind, 2) as address:
                client = connect(address)
                client.wait_for_workers(2, timeout=300)
                roles = cluster_pids(client)
                pids = {p: ("parent" if p == os.getpid() else r.split("+")[0])
                        for p, r in roles.items()}
                pids.setdefault(os.getpid(), "parent")
                t = time.perf_counter()
                ex.prepare_dask(client, scen)
                oracle_columns(scen)
                t_or = time.perf_counter() - t
                summarize(f"Dask fresh {kind} (workers warming during the {t_or:.2f} s "
                          "oracle)", campaign(ex.run_dask(scen, client, tag="t0"),
                                              pids))
                summarize(f"Dask {kind}, second campaign", campaign(
                    ex.run_dask(scen, client, tag="t1"), pids))
                client.close()
        finally:
            ex.fly_batch = batch
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
