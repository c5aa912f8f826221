"""Where a Dask campaign loses against the local pool: a breakdown, measured in one run.

Flies the same scenarios as ``bench_campaign.py`` (60 s flights, a 10 % loss of one lift rotor
in cruise) on the local pool and then on a fresh Dask ``LocalCluster`` (N worker processes,
one thread each, loopback), each task wrapped so that it reports its process, its start and
end on the wall clock and the CPU time of its own thread and of its whole process. Printed:

- a fresh worker's warm-up, measured in a fresh interpreter: the imports of the flight code,
  the airframe load and :func:`~vtolftc.runners.campaign.execute.warm_up` (gain files and the
  numba kernels loaded from the cache);
- what crosses the wire per scenario: the pickled scenario and result row (bytes, us);
- per worker on the cluster: the time until its first task starts, the warm-up inside the
  first task (its wall time minus the flights'), the idle gaps between tasks (dispatch: the
  result to the scheduler and the next task back), the task overhead over its flights;
- the flights themselves: mean flight loop time on the pool and on the cluster (the same
  scenarios), and the CPU taken from the task thread by the worker's other threads (event
  loop: heartbeats, ticks, the memory monitor) and by the scheduler and nannies;
- wall time, rate and the Dask / pool ratio.

Measured (12:55-13:00 UTC 2026-12-02, load 17 rising to 29; 24 scenarios, 2 workers, the
workers' plugins registered just before the tasks, i.e. no oracle to hide the warm-up):

- a fresh worker: interpreter start 3.5 s, imports of the flight code 4.6 s (``-X
  importtime`` at load 10: 3.2 s, of which numba 1.1 s and scipy.sparse 0.7 s through the
  autopilot's optional OSQP allocator module), airframe 26 ms, warm-up (gain files, numba
  kernels from the cache) 1.9 s; its first 60 s flight 3.51 s against 3.42 s for the second:
  the worker's first task started 12.6-12.8 s after the submission, where the pool's forked
  workers start at once;
- on the wire: a scenario 665 B (85-167 us to pickle and unpickle), a row 933 B (8 us):
  < 0.01 % of a flight (Arrow would change nothing);
- dispatch (one 60 s scenario per task): gaps between tasks 25-42 ms (median), a task's
  overhead over its flights 38-56 ms median, 0.4-0.7 % of 8-13 s flights;
- the workers' other threads (event loop) took 1.4 % of their busy time (profiler paused);
  the scheduler and client 6.8 s, the two nannies 13.6 s and the workers 34.5 s of CPU
  over the 182 s campaign: the Dask processes' background costs CPU at a fixed rate per
  second (idle LocalCluster: 13-14 % of a core, 7.9 % since the round-10 plugins);
- the rate ratio (0.53x) and the flight-time ratio (1.72) of that run measure the load's
  rise between the pool and the cluster, not Dask.

At load 2 (13:51, ``--scenarios 4``, a smoke run): a fresh worker's first task started
1.6-2.1 s after the submission (its warm-up; the 4 flights took 1.3-1.9 s each), gaps
between tasks 2-6 ms, a task's overhead over its flight 4.5 ms (0.3 %), the Dask flights
took 1.023x the pool's flight time, the workers' other threads 1.3-1.4 % of their busy time.

Round 13 (branch dask-13, 04:03-04:08 UTC 2026-12-03, load 11.5-13.6, ``--scenarios 8
--cluster tcp`` without and with ``--preload``, interleaved, two pairs; a fresh ``dask
scheduler`` + ``dask worker --nworkers 2`` each time, the campaign's plugins registered just
before the tasks, so no oracle hides anything): without the preload a worker's first task
started 5.2-6.9 s and 4.3-9.8 s after the submission (a fresh interpreter's imports of the
flight code: 1.7-5.0 s at this load, warm-up 0.24-0.36 s) and the workers took 7.15 and
6.55 s of CPU for the 8 flights; with ``--preload vtolftc.runners.campaign.dask_preload``
the first tasks started 0.06-0.14 s after it and the workers took 4.89 and 4.87 s: the
~2 s of imports and warm-up of the two workers moved into the cluster's start (5.1-6.0 s
-> 13.6-18.7 s, not in the campaign). Dispatch did not change: gaps between tasks 6-24 ms
median, a task's overhead over its flight 6-22 ms (0.2-0.5 %), the workers' other threads
0.7-0.9 % of their busy time; the scheduler 0.33-0.46 s of CPU, the nannies 0.03 s, the
client 0.05 s over the campaign. The importing itself: the flight code imported in 0.907 s
of CPU on this branch against 1.006 s on main (4 interleaved pairs, load 7), the optional
OSQP allocator's scipy.sparse now imported only when ``QPAllocator`` is used; the rest is
numba (~0.45 s), the metrics kernels' cache load at import and scipy.linalg, all used by
the flight.

    python benchmarks/bench_campaign_dask.py [--jobs 2] [--scenarios 24] [--batch B]
        [--no-warm]   # leave the campaign's worker warm-up out (as before issue 24's fix)
        [--cluster tcp [--preload]]   # `dask scheduler` + `dask worker` processes
"""

from __future__ import annotations

import argparse
import itertools
import os
import pickle
import statistics
import subprocess
import sys
import time
from typing import Any

HERE = os.path.dirname(os.path.abspath(__file__))


def _timed_batch(batch: list[Any]) -> dict[str, Any]:
    """A task: the batch's rows with the task's pid, wall-clock span and CPU times."""
    import threading

    from vtolftc.runners.campaign.execute import fly_batch

    t0, c0, p0 = time.time(), time.thread_time(), time.process_time()
    rows = fly_batch(batch)
    return {"pid": os.getpid(), "tid": threading.get_native_id(), "start": t0,
            "end": time.time(), "thread_cpu": time.thread_time() - c0,
            "process_cpu": time.process_time() - p0, "rows": rows}


def fresh_warm_up() -> dict[str, float]:
    """Import, airframe and warm-up times of a fresh interpreter (a new Dask worker's)."""
    code = (
        "import json, time\n"
        "t0 = time.perf_counter()\n"
        "import vtolftc.runners.campaign.execute as e\n"
        "import vtolftc.runners.scenario\n"
        "t1 = time.perf_counter()\n"
        "e.cached_airframe(None)\n"
        "t2 = time.perf_counter()\n"
        "from vtolftc.runners.campaign.scenarios import expand\n"
        "from vtolftc.runners.campaign.spec import parse_spec\n"
        f"import sys; sys.path.insert(0, {HERE!r}); from bench_campaign import SPEC\n"
        "scen = expand(parse_spec(SPEC))\n"
        "t3 = time.perf_counter()\n"
        "e.warm_up(scen)\n"
        "t4 = time.perf_counter()\n"
        "e.fly_scenario(scen[0])\n"
        "t5 = time.perf_counter()\n"
        "e.fly_scenario(scen[1])\n"
        "t6 = time.perf_counter()\n"
        "print(json.dumps({'imports': t1 - t0, 'airframe': t2 - t1, 'warm_up': t4 - t3,"
        " 'first_flight': t5 - t4, 'second_flight': t6 - t5}))\n")
    t = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=600)
    import json

    got = json.loads(out.stdout.strip().splitlines()[-1])
    got["interpreter"] = time.perf_counter() - t - sum(got.values())
    return got


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--scenarios", type=int, default=24)
    ap.add_argument("--batch", type=int, default=None, help="scenarios per Dask task")
    ap.add_argument("--no-warm", action="store_true",
                    help="no worker warm-up plugin (the harness before issue 24's fix)")
    ap.add_argument("--cluster", choices=("LocalCluster", "tcp"), default="LocalCluster",
                    help="a LocalCluster in this process, or `dask scheduler` + `dask worker` "
                         "processes (dask_clusters.local_tcp_cluster)")
    ap.add_argument("--preload", action="store_true",
                    help="tcp: workers started with --preload of the flight code")
    args = ap.parse_args()
    sys.path.insert(0, HERE)
    from bench_campaign import SPEC

    from vtolftc.runners.campaign import execute
    from vtolftc.runners.campaign.scenarios import expand
    from vtolftc.runners.campaign.spec import parse_spec

    scen = expand(parse_spec(SPEC))[: args.scenarios]
    n = len(scen)
    print(f"load average at start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"{n} scenarios of 60 s, {args.jobs} workers")

    w = fresh_warm_up()
    print(f"fresh worker (a new interpreter): start {w['interpreter']:.2f} s, imports "
          f"{w['imports']:.2f} s, airframe {w['airframe'] * 1e3:.0f} ms, warm_up "
          f"{w['warm_up']:.2f} s; then first 60 s flight {w['first_flight']:.2f} s, second "
          f"{w['second_flight']:.2f} s")

    execute.fly_scenario(scen[0])  # this process warm, as the campaign's parent is
    row = execute.fly_scenario(scen[1])
    reps = 200
    t = time.perf_counter()
    for _ in range(reps):
        ps = pickle.dumps(scen[0], protocol=5)
        pickle.loads(ps)
    t_s = (time.perf_counter() - t) / reps
    t = time.perf_counter()
    for _ in range(reps):
        pr = pickle.dumps(row, protocol=5)
        pickle.loads(pr)
    t_r = (time.perf_counter() - t) / reps
    print(f"per scenario on the wire: scenario {len(ps)} B ({t_s * 1e6:.0f} us pickle + "
          f"unpickle), row {len(pr)} B ({t_r * 1e6:.0f} us)")

    t = time.perf_counter()
    pool_rows = list(execute.run_local(scen, args.jobs))
    pool_wall = time.perf_counter() - t
    pool_run = {r["scenario_id"]: r["run_wall_time_s"] for r in pool_rows}
    print(f"local pool: {n} in {pool_wall:.1f} s = {60 * n / pool_wall:.1f} scenarios/min; "
          f"mean flight {statistics.mean(pool_run.values()):.3f} s")

    dask_run(args, scen, pool_wall, pool_run)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


def dask_run(args: argparse.Namespace, scen: list[Any], pool_wall: float,
             pool_run: dict[str, float]) -> None:
    """The same scenarios on a fresh cluster, every task timed; prints the breakdown."""
    from bench_campaign import fresh_cluster, proc_stat
    from distributed import Client, as_completed

    from vtolftc.runners.campaign import execute
    from vtolftc.runners.campaign.dask_plugin import PLUGIN_NAME, PauseProfiler
    from vtolftc.runners.campaign.dask_run import cluster_pids

    n = len(scen)
    t_start = time.perf_counter()
    with fresh_cluster(args.cluster, args.jobs, args.preload) as address, \
            Client(address, set_as_default=False) as client:
        client.wait_for_workers(args.jobs, timeout=300)
        t_cluster = time.perf_counter() - t_start
        roles = cluster_pids(client)
        procs: dict[str, list[int]] = {
            f"client+{roles.pop(os.getpid())} (this process)" if os.getpid() in roles
            else "client (this process)": [os.getpid()]}
        for pid, role in roles.items():
            procs.setdefault(role, []).append(pid)
        cpu0 = {k: sum(proc_stat(p)[1] for p in v) for k, v in procs.items()}
        t0w = time.time()
        t0 = time.perf_counter()
        if args.no_warm:
            client.register_plugin(PauseProfiler(), name=PLUGIN_NAME)
        else:
            execute.prepare_dask(client, scen)
        size = args.batch or execute.dask_batch_size(n, args.jobs)
        chunks = [scen[i:i + size] for i in range(0, n, size)]
        futs = client.map(_timed_batch, chunks, pure=False)
        tasks = []
        for f in as_completed(futs, loop=client.loop):
            tasks.append(f.result())
            f.release()
        wall = time.perf_counter() - t0
        cpu1 = {k: sum(proc_stat(p)[1] for p in v) for k, v in procs.items()}
    rows = [r for t in tasks for r in t["rows"]]
    dask_run_s = {r["scenario_id"]: r["run_wall_time_s"] for r in rows}
    same = sorted(set(dask_run_s) & set(pool_run))
    ratio_flight = statistics.mean(dask_run_s[k] / pool_run[k] for k in same)
    how = "no warm-up plugin" if args.no_warm else "warmed by prepare_dask"
    how += ", workers --preload" if args.preload and args.cluster == "tcp" else ""
    print(f"Dask fresh {args.cluster} (start {t_cluster:.1f} s, not included; {how}; batch "
          f"{size}): {n} in {wall:.1f} s = "
          f"{60 * n / wall:.1f} "
          f"scenarios/min -> Dask / pool {pool_wall / wall:.2f}x")
    print(f"  flights: Dask / pool flight loop time, same scenarios: {ratio_flight:.3f}")
    by_pid: dict[int, list[dict[str, Any]]] = {}
    for t in tasks:
        by_pid.setdefault(t["pid"], []).append(t)
    for pid, ts in sorted(by_pid.items()):
        ts.sort(key=lambda t: t["start"])
        first = ts[0]
        first_flights = sum(r["run_wall_time_s"] for r in first["rows"])
        gaps = [b["start"] - a["end"] for a, b in itertools.pairwise(ts)]
        over = [(t["end"] - t["start"]) - sum(r["run_wall_time_s"] for r in t["rows"])
                for t in ts[1:]]
        busy = sum(t["end"] - t["start"] for t in ts)
        other = sum(t["process_cpu"] - t["thread_cpu"] for t in ts)
        print(f"  worker {pid}: first task starts {first['start'] - t0w:.2f} s after submit; "
              f"first task {first['end'] - first['start']:.2f} s of which flights "
              f"{first_flights:.2f} s; {len(ts)} tasks; gaps between tasks median "
              f"{1e3 * statistics.median(gaps) if gaps else float('nan'):.1f} ms, total "
              f"{sum(gaps):.2f} s; later tasks' overhead over their flights median "
              f"{1e3 * statistics.median(over) if over else float('nan'):.1f} ms; other "
              f"threads' CPU during tasks {other:.2f} s of {busy:.1f} s busy "
              f"({100 * other / busy:.1f} %); idle after its last task "
              f"{t0w + wall - ts[-1]['end']:.2f} s")
    for k in procs:
        print(f"  CPU during the campaign, {k}: {cpu1[k] - cpu0[k]:.2f} s")


if __name__ == "__main__":
    main()
