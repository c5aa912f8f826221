"""Campaign throughput: scenarios per minute on this machine's cores, the campaign's own
overhead per scenario, and a Dask LocalCluster next to the local process pool.

The scenarios are 60 s flights of the paper's timeline that all fly to the end (a 10 % loss
of one lift rotor at t = 40 s in cruise, each rotor, the three controllers: 24 scenarios,
12 by default; beyond 24, the same at losses of 20 %, 30 %, ... for a campaign long enough
that a fresh cluster's start-up weighs what it does in a real one), so each one costs a full
60 s of simulation. Figures printed:

- the in-process run alone (``run_scenario``): wall time and real-time factor per scenario;
- the campaign's fixed costs: ``vtolftc`` start-up (imports), airframe load, autopilot and
  gain-file construction, first-flight compilation (numba cache load), Parquet part writes;
- the recoverability oracle of these scenarios (in the parent, before the flights): its
  reference flight and its LPs;
- the local pool (``--jobs N``) and Dask on fresh clusters of N workers (one thread each,
  loopback): wall time, scenarios per minute, overhead = (wall x workers / scenarios - mean
  run time) / mean run time, i.e. what the campaign adds to a scenario, and the CPU time of
  every process of the campaign per scenario (load-robust, unlike the wall times). Dask on
  a ``LocalCluster`` started here, first as before issue 24's round-10 fix (the oracle, then
  the flights: fresh workers warm in front of their first flights), then as ``vtolftc
  campaign --scheduler`` runs it now (the worker plugins registered first, so the workers
  warm while the parent computes the oracle) followed by a second campaign on the same
  cluster (a long-lived one); then a first campaign on a warm LocalCluster
  (``dask_clusters.warm_local_cluster``: workers forked from a forkserver that imported the flight
  code, warmed by the preload before they register); then the same two as the second on a
  ``tcp://`` cluster started separately (``dask scheduler`` and ``dask worker --nworkers N
  --nthreads 1`` processes), its workers without and then with ``--preload
  vtolftc.runners.campaign.dask_preload``. Ratios to the local pool's rate: the flights
  alone, and oracle + flights (as the CLI runs them).

``--memory N [--duration S]`` instead flies N short scenarios (S s each, default 4; the rotor
losses at N / 24 magnitudes) on the local pool with the parent writing Parquet parts as the
CLI does, samples the resident memory of the parent and of each worker (by pid) after each
row (:mod:`vtolftc.runners.campaign.memwatch`) and prints the parent's robust slope after the
first quarter and, for the workers (each replaced after ``WORKER_SCENARIOS``), the largest
growth in a worker's life and the slope of the largest worker's RSS, extrapolated to 2000
scenarios (target of issue 24: < 50 MB). It is ``bench_campaign_memory.py --backends pool``;
that benchmark also measures every process of fresh Dask clusters (LocalCluster, tcp://).

Targets (issue 24): >= 300 scenarios/min on 2 cores, overhead < 5 % of a scenario, Dask
within 0.9x of the local pool; memory of a 2000-scenario campaign < 50 MB per process.

Measured (docs/campaigns/README.md, "Speeding up the in-process run"): the warm 60 s flight
took 2.30 s on an idle core (26x real time) before the step was sped up; after, alternating
old and new trees on the loaded machine (load 7-9), it costs 0.74-0.90 of that in CPU time
(0.70 at load 4-6), i.e. ~1.6-2.1 s = 29-37x on an idle core, ~58-75 scenarios/min on 2
cores before overhead: short of the target. Where a step goes now: autopilot ~63 % (attitude
P-PID and allocation a quarter of it each), physics ~16 %, HIL codec ~9 %, metrics ~10 %.
Second round (P-PID axes and LQR law one compiled call each): attitude update 11.9 -> 2.9 us
per step; whole flights ~0.92 of the first round's CPU time (old mean 2.13 s, new 1.96 s at
load 9-11), ~31-41x on an idle core, ~62-82 scenarios/min on 2 cores before overhead.

Branch inproc-12 (2026-12-02 22:43-22:46 UTC, ``--jobs 2 --scenarios 24 --no-dask``, main's
tree then this branch's, load 7.1-8.9 on the 2 shared cores): warm 60 s flight 1.30 s
(main) and 1.85 s (branch) wall, the load's doing; the load-robust figure, the CPU of every
process of the campaign per scenario, 0.64 s (main) and 0.63 s (branch); local pool 29.8
and 33.6 scenarios/min, overhead +3.1 % and +1.2 %. The branch's gain is in the physics
kernel (10.99 -> 9.62 us per control step, same bits, ``bench_inproc.py``'s docstring),
~4 % of a step, within this noise. At 0.63 s CPU per scenario the 2 cores give ~190
scenarios/min at this load's CPU speed; 300/min needs 0.40 s per flight, i.e. the 26.7 us
per control step of the in-process target (the pool adds only 1-3 %): see
``bench_inproc.py`` for where the step's time goes and what would reach it.

Round 10 (Dask on a fresh cluster; one run of ``--scenarios 24`` at 13:13-13:36 UTC 2026-12-02,
load 17 rising to 32 on the 2 cores shared with 7 other engineers). The load moved the flight
itself from 8.3 s (pool) to 12.1, 16.9 and 21.4 s (the Dask campaigns run after it), so the
rate ratios printed (0.62x before, 0.48x after, 0.39x on the warm cluster) measure the load,
not the harness. What the harness adds per scenario, against the flights of the same
campaign, is load-robust: pool +0.7 %; Dask on a fresh LocalCluster +10.7 % before the fix
(workers warm after the oracle, in front of their first flights), +3.6 % after (warming
during the oracle), +0.8 % for a second campaign on the same cluster. Whole campaigns
(oracle + flights) in units of their own flight time: pool 1.04, Dask before 1.16 (0.90x),
after 1.14 (0.91x): on 2 cores the workers' warm-up slows the parent's oracle (6.9 -> 21.0
s) and only uses the core the oracle leaves idle. A separately started ``tcp://`` cluster:
+8.2 % over the flights even after a 45.5 s oracle (whole campaign 0.78x; not explained by
this run), +2.3 % for its second campaign. A second run (13:36-13:45, load 10 falling to 5):
pool +2.1 %; fresh LocalCluster before +17.7 %, after +4.9 %, second campaign +1.6 %; fresh
tcp:// cluster +5.1 %, second campaign +4.1 %. Not in these figures, the Dask processes'
background CPU (it slows the flights): an idle LocalCluster of 2 workers took 13.3-14.0 % of
a core before and 7.9 % after (profiler, ticks and the nannies' system monitor paused, their
memory check every 1 s; alternated in one run at load 19-20). The breakdown:
``bench_campaign_dask.py``.

Round 13 (branch dask-13: the worker preload ``vtolftc.runners.campaign.dask_preload``,
``dask_clusters.warm_local_cluster``, the flight code without scipy.sparse). One run at
03:54-04:03 UTC 2026-12-03, load 12 swinging between 8 and 14, the preloaded LocalCluster
then a plain ``LocalCluster(preload=...)`` (spawned workers). The rates swung with the load
(Dask / pool 0.77-1.59x, the in-process flight 2.1-4.5 s in the same run), so only the
harness's share is comparable: overhead over the flights, first campaign on a fresh
cluster: pool +2.5 %; LocalCluster, workers warming after the oracle (the old path)
+14.9 %, warming during the oracle (the CLI's path) +4.8 %, with the preload +1.7 %;
tcp:// cluster without the preload +1.9 % (its 8.6 s oracle, slowed by the load, hid the
workers' warm-up), with it +1.9 % behind a 2.5 s oracle; second campaigns +2.0 % (Local),
+5.2 % and +3.2 % (tcp). CPU of every process per scenario 0.52-0.70 s throughout, the pool
0.56 s. The preload moves a worker's imports and warm-up into the cluster's start: 2.2-3.7
s -> 13.3 s (LocalCluster, spawned) and 4.9 -> 17.5 s (tcp) at this load;
``warm_local_cluster`` forks its workers from a forkserver that imported the flight code
once: 2 preloaded workers up in 4.9-6.7 s with 1.5-1.6 s of CPU against 12.3-13.2 s and
3.0-3.5 s spawned (two interleaved pairs at load 13.5), so the warm cluster starts in about
the time of a plain one. Where the first campaign's gap comes from, when workers are not
preloaded (``bench_campaign_dask.py``): the fresh worker's interpreter and the flight
code's imports, 0.9 s of CPU each (1.0 s on main: scipy.sparse), numba, the metrics kernels'
cache load and scipy.linalg, all needed by the flight; at the idle machine's 0.46 s flight,
24 scenarios on 2 workers are ~5.5 s of flights, so ~1 s of start per worker is the 10-15 %
the lead measured. With the preload (tcp) or ``warm_local_cluster`` the first campaign flies
like the second (+1.7-1.9 % here, +1.9 % idle in the lead's second-campaign figure).
A second run (04:27-04:38, load 14 falling to 11, the flight between 1.6 and 9.1 s as the
load swung, so again no rate ratio holds) with ``warm_local_cluster`` as the preloaded
LocalCluster: pool +1.4 %; LocalCluster old path +15.8 %, CLI path +5.7 % (second campaign
+4.4 %); ``warm_local_cluster`` +1.8 %, its start 2.6 s against 5.9-7.2 s for the plain
LocalClusters of the same run; tcp:// +2.7 % (second +2.2 %), with the preload +1.6 %
(second +3.2 %). CPU of every process per scenario 0.61-0.86 s (pool 0.62 s).

``--whole`` instead times whole ``vtolftc campaign`` processes of the first ``--scenarios``
(start-up, oracle, flights, Parquet, report): the local pool, a fresh LocalCluster, a fresh
``tcp://`` cluster (its start not included), the pool again, and prints each Dask campaign's
ratio to the two pools' mean. Round 11 (2026-12-02, load 16.9-17.8, the author's memory
benchmark running beside it throughout): 12 scenarios, pool 45.5 and 53.2 s, fresh
LocalCluster 50.6 s (0.97x), fresh tcp:// 46.2 s (1.07x); 24 scenarios at load 8.1 falling
to 6.2: pool 41.4 and 39.6 s, LocalCluster 29.3 s (1.38x), tcp:// 26.4 s (1.53x), Dask's
extra processes taking a larger share of the loaded cores (not an idle figure); a run whose
load halved during it (15.3 -> 9.7) gave pools of 71.1 and 31.4 s (adjacent pairs: 1.12x
LocalCluster, 0.98x tcp://); at load 4.9-6.5 (16:54): pools 23.9 and 33.4 s, LocalCluster
22.5 s (1.06x the adjacent pool), tcp:// 34.2 s (0.98x). Every fresh cluster's whole campaign
was >= 0.90x its adjacent pool.

Session 15 (2026-12-03, the lead, idle machine, load 0.1-1.5, nothing else running): the
outer loops compiled (``bench_inproc.py``'s session 15), ``--jobs 2 --scenarios 24
--no-dask``, main against the session's base (1f51d91, clean-clone venvs), interleaved, 4
pairs: 296.8 / 300.2 / 302.0 / 289.9 against 231.4 / 232.1 / 298.6 / 232.3 scenarios/min
(0.38-0.40 s per flight against 0.49-0.51 s, one base run 0.40 s: the host's speed itself
jumps between runs), overhead +2.6-3.9 %. 300/min is reached in 2 of 4 runs: at the line,
without margin.

Session 16 (2026-12-03, branch inproc-16: the runner's fused tail call, the transition
kernels, the mode machine's update only where it can act, see ``bench_inproc.py``). Every
flight bit-identical (``command_digest.py`` unchanged; observer-free flights hashed step by
step equal). One warm 60 s flight of this spec's first scenario under callgrind: main 3,248.7
M instructions, branch 3,057.0 M (x0.941). ``--jobs 2 --scenarios 24 --no-dask`` on each tree
back to back, two pairs, other helpers' jobs running (not a quiet minute): load 3.2-3.9, main
then branch: CPU of every process per scenario 0.43 / 0.38 s, pool 54.0 / 117.1
scenarios/min (the pool's flights took 2.10 / 1.01 s of wall time against a warm in-process
0.39 / 0.88 s: the load's doing), overhead +6.0 / +1.4 %; load 1.7-2.3, branch then main:
CPU 0.41 / 0.41 s per scenario, pool 101.8 / 156.9 scenarios/min (flights 1.15 / 0.75 s
wall). The wall-time rates measure the neighbours, not the code; by the instruction count
the branch's flight is ~6 % cheaper, i.e. main's idle 289.9-302.0/min would be ~305-320/min:
a small margin, not the 10-15 % asked (to be confirmed idle).
The lead's idle check after the merge (14:21-14:23 UTC, a new machine of this kind: a Xeon
with AVX512_SPR, nothing else running, load 1.4-1.6; session 15's base 1be7cc4 from its
clean-clone venv against main, interleaved, 3 pairs): base 290.0 / 294.5 / 300.0, main
292.7 / 318.6 / 312.7 scenarios/min; CPU of every process per scenario 0.41 / 0.40 / 0.40
against 0.41 / 0.37 / 0.38 s; overhead +1.6-2.2 % (base +1.9-2.1 %). 300/min is passed in 2
of 3 runs, by 4-6 %.

Session 17 (2026-12-03, branch inproc-17: the P-PID step inside the allocation's compiled
call, the runner's reused decode buffers, see ``bench_inproc.py``). Every flight
bit-identical (``command_digest.py`` unchanged; observer-free flights hashed step by step and
this spec's first three result rows equal to main's). One warm 60 s flight of this spec's
first scenario under callgrind: main 3,060.5 M instructions, branch 2,960.4 M (x0.967).
Thread CPU per control step of that flight, 7 interleaved main/branch pairs at load
11.3-15.1: medians 30.3 / 29.2 us, pair ratio median 0.983. On the lead's idle figures
(292.7-318.6/min, 0.37-0.40 s per flight) x0.967 is ~0.36-0.39 s per flight, ~300-330/min:
a few per cent of margin at best, not the 10-15 % asked. ``bench_campaign`` itself not run
(the cores were shared 4-7 ways all session: its wall-time rates would measure the
neighbours).

    .venv/bin/python benchmarks/bench_campaign.py [--jobs 2] [--scenarios 24]
    .venv/bin/python benchmarks/bench_campaign.py --whole [--scenarios 24]
    .venv/bin/python benchmarks/bench_campaign.py --memory 2000 [--duration 4]

The lead's idle run (main with inproc-17 merged, 17:08-17:09 UTC, load 1.4 -> 2.1, ``--jobs 2
--scenarios 24``, one run): in-process 0.40 s per 60 s scenario (151.3x); local pool 296.0
scenarios/min, overhead +2.6 %; Dask LocalCluster 243.2-271.4/min (flights 0.82-0.92x of the
pool; 0.91x with ``--preload``, 0.92x on a warm cluster's second campaign), tcp:// 250.6-268.6
(0.85-0.91x). 300/min was missed by 1 %: session 16 measured 292.7-318.6 on the same code path.

Session 18 (2026-12-03, branch dask-18: where a fresh Dask cluster loses, and the scheduler
quieted during a campaign; ``bench_campaign_timeline.py`` has the per-worker timelines and
docs/campaigns/README.md, "Where a Dask campaign loses, per worker", the table). Not the
tail (the scheduler's queuing already balances 12/12, the early worker idle 0.02-0.41 s at
the end against the pool's 0.01-0.86 s), not dispatch (gaps 1.4-7.1 ms, < 1 %): a fresh
worker's start, ~0.7 s of CPU each (~2 flights; 14-18 % of this campaign's flights, which
the pool's forked workers never pay), and Dask's own processes, ~3-5 % of the CPU.
``bench_campaign.py --jobs 2 --scenarios 24``, main then this branch, two interleaved pairs
(18:49-18:58 UTC, load 2.1 rising to 5.5 and falling to 3.5; other helpers' jobs came and
went within runs, so the wall-time rates swung 0.57-1.88x of the pool in both trees and
say nothing here). The load-robust figure, CPU of every process per scenario (the bench's
two digits), the pool's in the same run first: main 0.40 / 0.39 s, Dask fresh
``LocalCluster`` (the CLI's path) 0.45 / 0.45, its second campaign 0.40 / 0.41, fresh
``tcp://`` 0.42 / 0.45, second 0.42 / 0.41; branch 0.40 / 0.37 s, fresh ``LocalCluster`` 0.43 /
0.40, second 0.40 / 0.38, fresh ``tcp://`` 0.44 / 0.40, second 0.40 / 0.38. As a rate on 2
saturated cores (the pool's CPU over Dask's): fresh ``LocalCluster`` 0.89x / 0.87x -> 0.93x /
0.93x, fresh ``tcp://`` 0.95x / 0.87x -> 0.91x / 0.93x, second campaigns 0.95-1.00x ->
0.97-1.00x: in the right direction, by more than the ~1 % the quieting was measured to
save, within the bench's rounding (0.01 s is 2.5 %) and this load's spread.

Session 19 (main with dask-18 merged, idle machine, 2026-12-03 22:17-22:31 UTC, load 0.1-2.1;
each ratio within one run; docs/campaigns/README.md, "The idle figures (issue 24, session
19)", has the table): ``--scenarios 24``: in-process 0.29 s per flight (209.6x), local pool
413.9 scenarios/min, overhead +2.6 % (406.9, +3.9 % with bytecode caches); Dask with warm
workers (preloaded, or a second campaign) 0.95-0.98x; fresh clusters without the preload
0.85-0.90x oracle + flights, 0.89-0.94x flights alone. ``--scenarios 96`` (two runs):
pool 415.8 / 420.1 scenarios/min, +2.0 %; every Dask configuration 0.90-0.98x, preloaded
0.96-0.97x. ``--whole``: fresh ``LocalCluster`` / ``tcp://`` 0.88x / 0.86x at 24 scenarios,
0.95x / 0.92x at 96. What a fresh worker without the preload pays before its first flight,
in a fresh interpreter: ``distributed`` 0.33-0.35 s of CPU, the flight code 0.45 s (numba's
import ~0.15 s, its first target and typing-context set-up ~0.23 s with the SciPy BLAS check
it makes, this package's modules ~0.07 s), warm-up 0.10 s; this sandbox's
``PYTHONDONTWRITEBYTECODE=1`` adds 0.07 s (this package's modules compiled from source in
every process).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

SPEC = """
[campaign]
name = "bench"
duration_s = 60.0
controllers = ["gs-shif", "shif", "lqr"]
phases = ["cruise"]
[[faults]]
family = "rotor-loss-10"
generate = "each"
actuators = ["lift_rotors"]
kinds = ["loss"]
magnitudes = [0.1]
"""


def spec_of(n: int) -> str:
    """The campaign of ``n`` scenarios: :data:`SPEC` with as many loss magnitudes (0.1, 0.2,
    ...) as 24 scenarios each need."""
    k = -(-n // 24)
    return SPEC.replace("magnitudes = [0.1]",
                        f"magnitudes = {[round(0.1 * (i + 1), 1) for i in range(k)]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--scenarios", type=int, default=12,
                    help="24 per loss magnitude (10 %%, 20 %%, ... 100 %%): at most 240")
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--memory", type=int, default=0, metavar="N",
                    help="memory run: N short scenarios, RSS growth per process")
    ap.add_argument("--duration", type=float, default=4.0, help="memory run: s per scenario")
    ap.add_argument("--whole", action="store_true",
                    help="whole `vtolftc campaign` runs: pool, fresh LocalCluster, fresh "
                         "tcp:// cluster, pool again")
    args = ap.parse_args()
    if args.memory:
        memory_run(args.memory, args.duration, args.jobs)
        return
    if args.whole:
        whole_runs(args.scenarios, args.jobs)
        return

    from vtolftc.runners.campaign.execute import fly_scenario, run_local
    from vtolftc.runners.campaign.results import PartWriter
    from vtolftc.runners.campaign.scenarios import expand
    from vtolftc.runners.campaign.spec import parse_spec

    if not 1 <= args.scenarios <= 240:
        ap.error("--scenarios: give 1 to 240 (24 per loss magnitude, 10 % to 100 %)")
    scen = expand(parse_spec(spec_of(args.scenarios)))[: args.scenarios]
    n = len(scen)
    print(f"load average at start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"{n} scenarios of 60 s")

    # fixed costs
    t = time.perf_counter()
    subprocess.run([sys.executable, "-c",
                    "from vtolftc.cli.main import build_parser; build_parser()"], check=True)
    t_start = time.perf_counter() - t
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.autopilot.autopilot import Autopilot

    t = time.perf_counter()
    af = load_airframe()
    t_af = time.perf_counter() - t
    t = time.perf_counter()
    for ctl in ("gs-shif", "shif", "lqr"):
        Autopilot(af, controller=ctl)
    t_ap = (time.perf_counter() - t) / 3
    t = time.perf_counter()
    first = fly_scenario(scen[0])
    t_first = time.perf_counter() - t
    t_compile = t_first - first["run_wall_time_s"]

    # the run alone, in this process (warm)
    rows = [fly_scenario(sc) for sc in scen[: min(n, 3)]]
    run_s = statistics.mean(r["run_wall_time_s"] for r in rows)
    task_s = statistics.mean(r["wall_time_s"] for r in rows)
    with tempfile.TemporaryDirectory() as d:
        w = PartWriter(Path(d), batch=8)
        t = time.perf_counter()
        for _ in range(3):
            for r in rows:
                w.add(r)
            w.flush()
        t_write = (time.perf_counter() - t) / (3 * len(rows))
    print(f"\nin-process run (warm, mean of {len(rows)}): {run_s:.2f} s per 60 s scenario "
          f"= {60.0 / run_s:.1f}x real time; task incl. set-up {task_s:.2f} s")
    print(f"fixed costs: vtolftc start-up {t_start:.2f} s (once per campaign), airframe load "
          f"{t_af * 1e3:.1f} ms (once per worker), autopilot + gains {t_ap * 1e3:.1f} ms per "
          f"scenario, first flight compile/cache load {t_compile:.2f} s (once per worker), "
          f"Parquet write {t_write * 1e3:.2f} ms per row")

    from vtolftc.runners.campaign.oracle import oracle_columns

    t = time.perf_counter()
    oracle_columns(scen)
    t_oracle = time.perf_counter() - t
    print(f"recoverability oracle (parent, before the flights): {t_oracle:.2f} s for {n} "
          f"scenarios (one reference flight to {max(s.fault_time_s for s in scen):g} s and "
          f"{len({(s.fault_set.faults, s.fault_time_s) for s in scen})} LPs)")

    def report(label: str, wall: float, workers: int, got: list[dict]) -> float:
        mean_run = statistics.mean(r["run_wall_time_s"] for r in got)
        per = wall * workers / len(got)
        rate = 60.0 * len(got) / wall
        print(f"{label}: {len(got)} scenarios in {wall:.1f} s = {rate:.1f} "
              f"scenarios/min; per scenario {per:.2f} s of a worker vs {mean_run:.2f} s of "
              f"flight -> overhead {100 * (per - mean_run) / mean_run:+.1f} % "
              f"(target >= 300 scenarios/min, < 5 %)")
        return rate

    def fly(stream: Any) -> tuple[float, list[dict]]:
        with tempfile.TemporaryDirectory() as d:
            c = cpu_s()
            t = time.perf_counter()
            w = PartWriter(Path(d))
            got = []
            for r in stream:
                w.add(r)
                got.append(r)
            w.close()
            wall = time.perf_counter() - t
            print(f"  CPU of every process of the campaign (this one, its workers, a cluster's "
                  f"scheduler and nannies): {(cpu_s() - c) / len(got):.2f} s per scenario")
            return wall, got

    wall, got = fly(run_local(scen, args.jobs))
    pool_rate = report(f"local pool ({args.jobs} processes, start-up included)", wall,
                       args.jobs, got)

    if not args.no_dask:
        for kind, early, second, preload in (
                ("LocalCluster", False, False, False), ("LocalCluster", True, True, False),
                ("LocalCluster", True, False, True), ("tcp", True, True, False),
                ("tcp", True, True, True)):
            dask_runs(kind, scen, args.jobs, t_oracle, pool_rate, report, fly, early=early,
                      second=second, preload=preload)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


def proc_stat(pid: int) -> tuple[int, float] | None:
    """(parent pid, user + system CPU s) of process ``pid`` from ``/proc`` (Linux); None
    when it is gone."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    tick = os.sysconf("SC_CLK_TCK")
    return int(fields[1]), (int(fields[11]) + int(fields[12])) / tick


def cpu_s() -> float:
    """CPU time (user + system, s) of this process, its descendants alive and the children
    it has waited for (the pool's replaced workers)."""
    from vtolftc.runners.campaign.memwatch import child_pids

    t = os.times()
    total = t.user + t.system + t.children_user + t.children_system
    for pid in child_pids():
        st = proc_stat(pid)
        if st is not None:
            total += st[1]
    return total


@contextlib.contextmanager
def fresh_cluster(kind: str, jobs: int, preload: bool = False) -> Iterator[str]:
    """A fresh Dask cluster of ``jobs`` worker processes (one thread each) on 127.0.0.1:
    ``LocalCluster`` (started in this process, as a script or notebook does) or ``tcp`` (a
    ``dask scheduler`` and a ``dask worker --nworkers N --nthreads 1`` started as separate
    processes, as a deployment is: :func:`vtolftc.runners.campaign.dask_clusters.local_tcp_cluster`,
    with ``preload`` the workers of either start with the preload
    :data:`vtolftc.runners.campaign.dask_clusters.PRELOAD`, warm before they register; the
    LocalCluster's then fork from a forkserver that imported the flight code:
    :func:`~vtolftc.runners.campaign.dask_clusters.warm_local_cluster`). Yields the
    scheduler's address; stops what it started."""
    from vtolftc.runners.campaign.dask_clusters import local_tcp_cluster, warm_local_cluster

    if kind == "LocalCluster" and preload:
        with warm_local_cluster(jobs) as cluster:
            yield cluster.scheduler_address
        return
    if kind == "LocalCluster":
        from distributed import LocalCluster

        with LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                          host="127.0.0.1", dashboard_address=None) as cluster:
            yield cluster.scheduler_address
        return
    with local_tcp_cluster(jobs, preload=preload) as address:
        yield address


def dask_runs(kind: str, scen: list[Any], jobs: int, t_oracle: float, pool_rate: float,
              report: Any, fly: Any, *, early: bool = True, second: bool = True,
              preload: bool = False) -> None:
    """Campaigns on a fresh ``kind`` cluster, ratios to the local pool's rate.

    The first as ``vtolftc campaign --scheduler`` runs it: with ``early`` (since issue 24's
    fix) the client connects and registers the campaign's worker plugins (the workers start
    warming), then the parent computes the oracle, then the flights; without (before), the
    oracle first and the workers warm in front of their first flights. Compared with the
    pool's oracle + flights (its workers fork from the warm parent), and its flights alone.
    With ``second``, a second campaign on the same cluster (a long-lived one, as a
    deployment is): the flights alone. ``preload``: the cluster's workers start with the
    preload ``vtolftc.runners.campaign.dask_preload`` (warm before they register; the
    cluster start printed then includes their imports and warm-up)."""
    from vtolftc.runners.campaign.dask_run import connect
    from vtolftc.runners.campaign.execute import prepare_dask, run_dask
    from vtolftc.runners.campaign.oracle import oracle_columns

    t0 = time.perf_counter()
    with fresh_cluster(kind, jobs, preload) as address:
        client = connect(address)
        try:
            client.wait_for_workers(jobs, timeout=300)
            t_cluster = time.perf_counter() - t0
            t = time.perf_counter()
            if early:
                prepare_dask(client, scen)
            oracle_columns(scen)
            t_or = time.perf_counter() - t
            wall, got = fly(run_dask(scen, client, tag="bench0"))
            how = ("workers warming during the oracle" if early else
                   "before the fix: the workers warm after the oracle")
            label = (f"Dask {kind}{' --preload' if preload else ''} ({jobs} workers; "
                     f"cluster start {t_cluster:.1f} s not included)")
            rate = report(f"{label}, first campaign on the fresh cluster ({how}), flights",
                          wall, jobs, got)
            n = len(got)
            pool_whole = 60.0 * n / (t_oracle + 60.0 * n / pool_rate)
            dask_whole = 60.0 * n / (t_or + wall)
            print(f"  Dask / local pool: flights {rate / pool_rate:.2f}x; oracle + flights "
                  f"(as `vtolftc campaign` runs them; oracle {t_or:.1f} s here, "
                  f"{t_oracle:.1f} s before the pool) {dask_whole / pool_whole:.2f}x "
                  "(target >= 0.9x)")
            if second:
                wall, got = fly(run_dask(scen, client, tag="bench1"))
                rate = report(f"{label}, second campaign on the same cluster", wall, jobs, got)
                print(f"  Dask / local pool: {rate / pool_rate:.2f}x (target >= 0.9x)")
        finally:
            client.close()


def whole_runs(n: int, jobs: int) -> None:
    """Whole campaigns as a user runs them, each a fresh ``vtolftc campaign`` process timed
    from start to exit (start-up, oracle, flights, Parquet, report): the local pool, then a
    fresh LocalCluster's and a fresh ``tcp://`` cluster's (cluster start not included: the
    clock starts once its workers have registered), then the pool again, so that a load
    drifting during the run shows as the two pools' spread. Ratios: the mean pool wall time
    over each Dask one (target >= 0.9x). An untimed campaign of 2 s flights first loads the
    file and numba caches."""
    spec = spec_of(n).replace('name = "bench"', f'name = "whole{n}"')
    vtolftc = str(Path(sys.executable).parent / "vtolftc")
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "spec.toml").write_text(spec)
        from vtolftc.runners.campaign.scenarios import expand
        from vtolftc.runners.campaign.spec import parse_spec

        m = len(expand(parse_spec(spec)))
        if m > n:  # the first n scenarios: the spec's rotors cut down
            rotors = ["rotor_1a", "rotor_1b", "rotor_2a", "rotor_2b", "rotor_3a", "rotor_3b",
                      "rotor_4a", "rotor_4b"][: max(1, n // 3)]
            spec = spec.replace('actuators = ["lift_rotors"]', f"actuators = {rotors!r}"
                                .replace("'", '"'))
            (Path(d) / "spec.toml").write_text(spec)
        k = len(expand(parse_spec(spec)))
        print(f"load average at start: {os.getloadavg()[0]:.2f}; whole campaigns of {k} "
              f"scenarios of 60 s, {jobs} workers; {time.strftime('%H:%M:%S', time.gmtime())}"
              " UTC")

        def campaign(tag: str, *extra: str) -> float:
            t = time.perf_counter()
            subprocess.run([vtolftc, "campaign", str(Path(d) / "spec.toml"), "--out",
                            str(Path(d) / tag), "--no-progress", *extra], check=True,
                           stdout=subprocess.DEVNULL, timeout=3600)
            wall = time.perf_counter() - t
            print(f"  {tag}: {wall:.1f} s (load {os.getloadavg()[0]:.2f})", flush=True)
            return wall

        (Path(d) / "warm.toml").write_text(spec.replace("duration_s = 60.0", "duration_s = 2.0")
                                           .replace('phases = ["cruise"]', "phases = [1.0]"))
        subprocess.run([vtolftc, "campaign", str(Path(d) / "warm.toml"), "--out",  # caches
                        str(Path(d) / "warm"), "--no-progress", "--jobs", str(jobs)],
                       check=True, stdout=subprocess.DEVNULL, timeout=3600)
        walls = {"pool": [campaign("pool-1", "--jobs", str(jobs))]}
        for kind in ("LocalCluster", "tcp"):
            with fresh_cluster(kind, jobs) as address:
                from distributed import Client

                with Client(address, set_as_default=False, timeout="60s") as c:
                    c.wait_for_workers(jobs, timeout=300)
                walls[kind] = [campaign(f"dask-{kind}", "--scheduler", address)]
        walls["pool"].append(campaign("pool-2", "--jobs", str(jobs)))
    pool = statistics.mean(walls["pool"])
    for kind in ("LocalCluster", "tcp"):
        w = walls[kind][0]
        print(f"whole campaign, Dask fresh {kind} / pool: {pool / w:.2f}x (pool {pool:.1f} s, "
              f"mean of {walls['pool'][0]:.1f} and {walls['pool'][1]:.1f}; Dask {w:.1f} s; "
              "target >= 0.9x)")
    print(f"load average at end: {os.getloadavg()[0]:.2f}; "
          f"{time.strftime('%H:%M:%S', time.gmtime())} UTC")


def memory_run(n: int, duration_s: float, jobs: int) -> None:
    """Fly ``n`` short scenarios on the local pool and print the RSS growth per process
    (``bench_campaign_memory.py --backends pool``, which also measures the Dask clusters)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_campaign_memory import memory_spec, pool_run

    from vtolftc.runners.campaign.scenarios import expand
    from vtolftc.runners.campaign.spec import parse_spec

    scen = expand(parse_spec(memory_spec(n, duration_s)))[:n]
    print(f"load average at start: {os.getloadavg()[0]:.2f}; memory run: {len(scen)} "
          f"scenarios of {duration_s:g} s on {jobs} processes")
    pool_run(scen, jobs)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
