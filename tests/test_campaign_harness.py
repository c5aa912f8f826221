"""The campaign harness around the flights: per-process caches, the forked local pool, batched
Dask tasks that are released, and memory that does not grow with the number of scenarios."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from vtolftc.runners.campaign import execute
from vtolftc.runners.campaign.memwatch import RssWatch, child_pids, robust_slope, rss_bytes
from vtolftc.runners.campaign.results import TIMING_COLUMNS, read_results
from vtolftc.runners.campaign.scenarios import expand
from vtolftc.runners.campaign.spec import parse_spec

# Four short flights using the axes that change a flight: two controllers x two fault sets,
# a gusty wind, seeded state noise, a perturbed airframe.
SHORT = """
[campaign]
name = "short"
duration_s = 4.0
controllers = ["gs-shif", "lqr"]
phases = [2.0]

[[faults]]
family = "rotor"
generate = "each"
actuators = ["rotor_2a"]
kinds = ["off", "loss"]
magnitudes = [0.5]

[[wind]]
name = "gust"
steady_ned_m_s = [1.0, 2.0, 0.0]
gusts = [{ after_fault_s = 0.5, duration_s = 1.0, amplitude_ned_m_s = [0.0, 3.0, -0.5] }]

[[perturbation]]
name = "heavy"
mass_scale = 1.05
inertia_scale = [1.1, 0.95, 1.0]
cg_offset_m = [0.01, 0.0, 0.005]

[noise]
level = "typical"
seeds = [7]
"""


def _same_rows(a: list[dict], b: list[dict]) -> None:
    """Every value bit for bit (NaN equal to NaN), except the wall times."""
    a = sorted(a, key=lambda r: r["index"])
    b = sorted(b, key=lambda r: r["index"])
    assert [r["scenario_id"] for r in a] == [r["scenario_id"] for r in b]
    for ra, rb in zip(a, b, strict=True):
        assert list(ra) == list(rb)  # the same columns, in the same order
        for k, v in ra.items():
            if k in TIMING_COLUMNS:
                continue
            w = rb[k]
            if isinstance(v, float):
                assert np.float64(v).view(np.int64) == np.float64(w).view(np.int64), k
            else:
                assert v == w, k


def test_cached_timeline_is_paper_scenario():
    from vtolftc.firmware_sim.vehicle.faults import Fault
    from vtolftc.runners.scenario import paper_scenario

    for sc in expand(parse_spec(SHORT)):
        faults = [Fault(a, kind, loss, sc.fault_time_s) for a, kind, loss in sc.fault_set.faults]
        # an extra fault at the transition command's time: commands keep their place first
        faults.append(Fault("elevator", "stuck", 0.0, 20.0))
        got = execute._campaign_scenario(sc, faults)
        want = paper_scenario(0, sc.duration_s, airframe=execute.cached_airframe(None),
                              extra_faults=faults, window_start_s=sc.window_start_s)
        assert repr(got) == repr(want)
    assert execute.base_scenario(4.0) is execute.base_scenario(4.0)  # built once


def test_pool_forks_only_a_single_threaded_process():
    stop = threading.Event()
    t = threading.Thread(target=stop.wait, daemon=True)
    t.start()
    try:
        assert execute.pool_context().get_start_method() == "forkserver"
    finally:
        stop.set()
        t.join(timeout=10)
    code = ("from vtolftc.runners.campaign.execute import pool_context; "
            "print(pool_context().get_start_method())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True)
    assert out.stdout.strip() == "fork"


def test_dask_batch_size():
    from vtolftc.runners.campaign.dask_run import dask_batch_size

    assert execute.dask_batch_size(12, 2) == 1      # 60 s flights: one per task
    assert dask_batch_size(24, 2, 60.0) == 1
    assert dask_batch_size(2000, 2, 60.0) == 1
    assert dask_batch_size(2000, 2, 2.0) == 30      # 60 simulated seconds per task
    assert dask_batch_size(2000, 2, 4.0) == 15
    assert dask_batch_size(2000, 2, 7.0) == 9       # rounded up
    assert dask_batch_size(100, 2, 2.0) == 6        # but 8 tasks per worker at least
    assert dask_batch_size(2000, 200, 2.0) == 1
    assert dask_batch_size(0, 0) == 1


def test_robust_slope_ignores_jumps():
    x = np.arange(200.0)
    y = 1e8 + 3.0 * x
    y[50:] += 4e6   # one step of the allocator
    y[120] += 1e9   # one outlier
    assert robust_slope(x, y) == pytest.approx(3.0, abs=1e-9)
    assert np.isnan(robust_slope([1.0, 1.0], [2.0, 3.0]))
    with pytest.raises(AssertionError):  # the ordinary least squares fit is pulled away
        assert np.polyfit(x, y, 1)[0] == pytest.approx(3.0, rel=0.5)


def test_rss_of_this_process_and_a_child():
    assert rss_bytes(10 ** 9) is None
    big = np.ones(40 * 2 ** 20 // 8)  # 40 MB touched
    own = rss_bytes(__import__("os").getpid())
    assert own is not None and own > big.nbytes
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert proc.pid in child_pids()
        w = RssWatch()
        for n in range(6):
            w.sample(n)
        assert set(w.samples) >= {w.parent, proc.pid}
        g = w.growth(2000, skip=0.0)
        assert abs(g[w.parent]["slope_b_per_scenario"]) < 1e6
    finally:
        proc.kill()
        proc.wait(timeout=30)


@pytest.mark.slow
def test_forked_pool_and_batched_dask_equal_one_process():
    from distributed import Client, LocalCluster

    from vtolftc.runners.campaign.dask_plugin import (
        NANNY_PLUGIN_NAME,
        PLUGIN_NAME,
        WARM_PLUGIN_NAME,
        PauseProfiler,
        QuietNanny,
    )

    scen = expand(parse_spec(SHORT))
    assert len(scen) == 4
    serial = [execute.fly_scenario(sc) for sc in scen]
    assert all(r["error"] == "" for r in serial)
    assert len({r["max_attitude_excursion_deg"] for r in serial}) == 4  # they differ
    _same_rows(serial, list(execute.run_local(scen, 2)))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        with Client(cluster.scheduler_address, set_as_default=False) as c:
            # fresh workers warm themselves for the campaign once its plugins are registered,
            # before any task reaches them
            c.wait_for_workers(2, timeout=120)
            assert all(v == [] for v in c.run(lambda: sorted(execute._WARM)).values())
            execute.prepare_dask(c, scen)
            keys = sorted(execute.warm_keys(scen), key=repr)

            def warmed(dask_worker):
                fut = dask_worker.plugins[WARM_PLUGIN_NAME].pending
                return fut is not None and fut.done() and set(keys) <= execute._WARM

            deadline = time.monotonic() + 300
            while not all(c.run(warmed).values()):
                assert time.monotonic() < deadline, c.run(lambda: sorted(execute._WARM))
                time.sleep(0.2)
            # a client kept open by the caller (as vtolftc campaign does)
            _same_rows(serial, list(execute.run_dask(scen, c, tag="c", batch=2)))
            assert not any(set(v) & {PLUGIN_NAME, WARM_PLUGIN_NAME} for v in c.run(
                lambda dask_worker: list(dask_worker.plugins)).values())  # unregistered
            assert not any(NANNY_PLUGIN_NAME in v for v in c.run(
                lambda dask_worker: list(dask_worker.plugins), nanny=True).values())
        rows = list(execute.run_dask(scen, cluster.scheduler_address, tag="t", batch=3))
        _same_rows(serial, rows)
        with Client(cluster.scheduler_address, set_as_default=False) as c:
            left = c.run_on_scheduler(lambda dask_scheduler: [
                str(k) for k in dask_scheduler.tasks if "vtolftc-t-" in str(k)])
            assert left == []  # every task released: no result held on a worker

            def profiling(dask_worker):
                pcs = dask_worker.periodic_callbacks
                return pcs["profile"].is_running(), pcs["tick"].is_running()

            def nanny_state(dask_worker):  # run on the nannies
                pcs = dask_worker.periodic_callbacks
                return (pcs["tick"].is_running(), pcs["monitor"].is_running(),
                        pcs["memory_monitor"].callback_time)

            on = {(True, True)}
            assert set(c.run(profiling).values()) == on  # back after the campaign
            nanny_on = set(c.run(nanny_state, nanny=True).values())
            assert nanny_on == {(True, True, 100.0)}
            c.register_plugin(PauseProfiler(), name=PLUGIN_NAME)
            c.register_plugin(QuietNanny(), name=NANNY_PLUGIN_NAME)
            assert set(c.run(profiling).values()) == {(False, False)}  # paused meanwhile
            assert set(c.run(nanny_state, nanny=True).values()) == {(False, False, 1000.0)}
            c.unregister_worker_plugin(PLUGIN_NAME)
            c.unregister_worker_plugin(NANNY_PLUGIN_NAME, nanny=True)
            assert set(c.run(profiling).values()) == on
            assert set(c.run(nanny_state, nanny=True).values()) == nanny_on


def test_the_flight_code_imports_without_scipy_sparse():
    """A fresh process (a Dask worker's) importing the flight code leaves out the optional
    OSQP allocator's scipy.sparse (0.1 s of CPU, 0.5 s at load 10); ``QPAllocator`` still
    imports on demand, and an unknown name of the package is still an AttributeError."""
    code = ("import sys\n"
            "import vtolftc.runners.campaign.execute, vtolftc.runners.scenario\n"
            "print('scipy.sparse' in sys.modules)\n"
            "import vtolftc.firmware_sim.autopilot.allocation as al\n"
            "print(al.QPAllocator.__name__, 'scipy.sparse' in sys.modules)\n"
            "print(hasattr(al, 'NoSuchAllocator'))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, check=True)
    assert out.stdout.split() == ["False", "QPAllocator", "True", "False"]


@pytest.mark.slow
def test_preloaded_workers_are_warm_before_a_task_and_fly_the_same_rows():
    """``dask worker --preload vtolftc.runners.campaign.dask_preload`` (a real scheduler and
    worker started as processes on 127.0.0.1): the worker has imported the flight code and
    warmed the shipped controllers before it registers, before any task; a worker started
    without the preload has not (the check tells them apart). The preloaded cluster flies the
    rows of one process, bit for bit; so does :func:`warm_local_cluster`'s, whose workers
    are forked from the forkserver."""
    from distributed import Client

    from vtolftc.runners.campaign.dask_clusters import local_tcp_cluster, warm_local_cluster
    from vtolftc.runners.campaign.dask_preload import preload_keys

    def worker_state(dask_worker):  # nested: pickled by value, it imports nothing on the worker
        ex = sys.modules.get("vtolftc.runners.campaign.execute")
        return {"flight_code": "vtolftc.runners.scenario" in sys.modules,
                "numba": "numba" in sys.modules,
                "warm": sorted(ex._WARM, key=repr) if ex is not None else [],
                "preload_s": getattr(dask_worker, "vtolftc_preload_s", None),
                "parent": os.getppid()}

    scen = expand(parse_spec(SHORT))
    serial = [execute.fly_scenario(sc) for sc in scen]
    want = sorted(preload_keys(), key=repr)
    assert set(execute.warm_keys(scen)) <= set(want)
    for preload in (False, True):
        with local_tcp_cluster(1, preload=preload, idle_timeout_s=300) as address, \
                Client(address, set_as_default=False, timeout="60s") as c:
            c.wait_for_workers(1, timeout=300)
            (state,) = c.run(worker_state).values()
            if not preload:
                assert state == {"flight_code": False, "numba": False, "warm": [],
                                 "preload_s": None, "parent": state["parent"]}
                continue
            assert state["flight_code"] and state["numba"]
            assert state["warm"] == want and state["preload_s"] > 0.0
            _same_rows(serial, list(execute.run_dask(scen, c, tag="preload", batch=2)))
    # a LocalCluster whose workers fork from the forkserver (not spawned by this process,
    # where the LocalCluster's nannies live), warm before a task, the same rows
    with warm_local_cluster(2) as cluster, \
            Client(cluster.scheduler_address, set_as_default=False) as c:
        c.wait_for_workers(2, timeout=300)
        states = list(c.run(worker_state).values())
        assert all(st["parent"] != os.getpid() for st in states), states
        assert all(st["flight_code"] and st["warm"] == want for st in states), states
        _same_rows(serial, list(execute.run_dask(scen, c, tag="forkserver", batch=1)))


MEMORY = """
[campaign]
name = "memory"
duration_s = 4.0
controllers = ["gs-shif", "shif", "lqr"]
phases = [2.0]

[[faults]]
family = "rotor-loss"
generate = "each"
actuators = ["lift_rotors"]
kinds = ["loss"]
magnitudes = [0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45]
"""


@pytest.mark.slow
def test_campaign_memory_does_not_grow_with_scenarios(tmp_path):
    """200 short scenarios on two workers, each replaced after 25 scenarios, with the parent
    writing Parquet parts. Issue 24: < 50 MB growth over 2000 scenarios for the parent and the
    workers. The parent: its robust RSS slope over the second half, times 2000. The workers:
    no worker grows by more than 50 MB in its life, and the robust slope of the largest
    worker's RSS against the scenario count, times 2000, stays < 50 MB (a fresh worker's
    allocators grow over its first few hundred flights before they settle, which the
    replacement cuts short; ``bench_campaign.py --memory 2000`` measures the real 2000)."""
    # in a fresh campaign process, as `vtolftc campaign` is (no test's threads: the pool forks)
    code = f"""
import json, sys
from vtolftc.runners.campaign import execute
from vtolftc.runners.campaign.memwatch import RssWatch
from vtolftc.runners.campaign.results import PartWriter
from vtolftc.runners.campaign.scenarios import expand
from vtolftc.runners.campaign.spec import parse_spec
assert execute.pool_context().get_start_method() == "fork"
scen = expand(parse_spec({MEMORY!r}))[:200]
watch = RssWatch()
writer = PartWriter({str(tmp_path)!r}, batch=8)
n = 0
for row in execute.run_local(scen, 2, worker_scenarios=25):
    writer.add(row)
    n += 1
    watch.sample(n)
writer.close()
json.dump({{"parent": watch.parent, "samples": watch.samples}}, sys.stdout)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600, check=True)
    got = json.loads(out.stdout)
    watch = RssWatch(parent=got["parent"],
                     samples={int(k): [tuple(x) for x in v] for k, v in got["samples"].items()})
    assert max(n for s in watch.samples.values() for n, _ in s) == 200
    assert read_results(tmp_path).num_rows == 200
    parent = watch.growth(2000, skip=0.5)[watch.parent]
    assert parent["growth_b"] < 50e6, parent
    workers = {pid: s for pid, s in watch.samples.items()
               if pid != watch.parent and len(s) >= 5}
    assert len(workers) >= 6, sorted(workers)  # replaced: 200 / 25 = 8 workers in all
    for pid, s in workers.items():
        assert s[-1][1] - s[0][1] < 50e6, (pid, s[0], s[-1])
    largest: dict[int, int] = {}
    for s in workers.values():
        for k, rss in s:
            largest[k] = max(largest.get(k, 0), rss)
    ks = sorted(k for k in largest if k >= 100)
    assert robust_slope(ks, [largest[k] for k in ks]) * 2000 < 50e6
