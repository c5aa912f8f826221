"""A Dask campaign quiets the cluster while it runs: the workers' profiler, ticks and system
monitor, the nannies' ticks and monitor, the scheduler's tick and monitor (session 18:
``dask_plugin.QuietScheduler``), each started again at the campaign's end or, for the
scheduler, when the campaign's client leaves without ending it."""

from __future__ import annotations

import time

import pytest

pytest.importorskip("distributed")

from vtolftc.runners.campaign import execute
from vtolftc.runners.campaign.dask_plugin import (
    MEMORY_CHECK_MS,
    SCHEDULER_PLUGIN_NAME,
    PauseProfiler,
    QuietNanny,
    QuietScheduler,
    quiet_scheduler_off,
)
from vtolftc.runners.campaign.scenarios import expand
from vtolftc.runners.campaign.spec import parse_spec


class _Callback:
    """A stand-in for tornado's PeriodicCallback: running or not, and its period (ms)."""

    def __init__(self, ms: float) -> None:
        self.callback_time = ms
        self.running = True

    def is_running(self) -> bool:
        return self.running

    def start(self) -> None:
        self.running = True

    def stop(self) -> None:
        self.running = False


class _Server:
    """A stand-in for a Dask server (worker, nanny, scheduler) and its periodic callbacks."""

    def __init__(self, *names: str) -> None:
        self.periodic_callbacks = {k: _Callback(1000.0 if k != "memory_monitor" else 100.0)
                                   for k in names}
        self.plugins: dict[str, object] = {}

    def state(self) -> dict[str, tuple[bool, float]]:
        return {k: (v.running, v.callback_time) for k, v in self.periodic_callbacks.items()}


WORKER = ("profile", "profile-cycle", "tick", "ticks", "monitor", "memory_monitor",
          "heartbeat", "find-missing", "keep-alive", "shift_counters")
SCHEDULER = ("tick", "ticks", "monitor", "stealing", "idle-timeout", "worker-ttl",
             "no-workers-timeout", "shift_counters")


def test_worker_nanny_plugins_pause_what_only_observes_and_restore_it():
    w = _Server(*WORKER)
    before = w.state()
    PauseProfiler().setup(w)
    off = {"profile", "profile-cycle", "tick", "ticks", "monitor"}
    assert w.state() == {k: ((k not in off),
                             MEMORY_CHECK_MS if k == "memory_monitor" else before[k][1])
                         for k in WORKER}
    PauseProfiler().setup(w)  # a second registration changes nothing
    PauseProfiler().teardown(w)
    assert w.state() == before
    n = _Server("tick", "ticks", "monitor", "memory_monitor", "shift_counters")
    before = n.state()
    QuietNanny().setup(n)
    assert n.state() == {"tick": (False, 1000.0), "ticks": (False, 1000.0),
                         "monitor": (False, 1000.0), "memory_monitor": (True, MEMORY_CHECK_MS),
                         "shift_counters": (True, 1000.0)}
    QuietNanny().teardown(n)
    assert n.state() == before


def test_quiet_scheduler_pauses_tick_and_monitor_until_its_client_leaves():
    s = _Server(*SCHEDULER)
    before = s.state()
    plugin = QuietScheduler("Client-campaign")
    assert plugin.idempotent and plugin.name == SCHEDULER_PLUGIN_NAME
    plugin.start(s)
    s.plugins[SCHEDULER_PLUGIN_NAME] = plugin
    quiet = {k: ((k not in ("tick", "ticks", "monitor")), v[1]) for k, v in before.items()}
    assert s.state() == quiet  # the scheduling callbacks (stealing, timeouts) keep running
    plugin.remove_client(s, "Client-other")  # another client leaving changes nothing
    assert s.state() == quiet and SCHEDULER_PLUGIN_NAME in s.plugins
    plugin.remove_client(s, "Client-campaign")  # the campaign's client gone: back on
    assert s.state() == before and SCHEDULER_PLUGIN_NAME not in s.plugins
    plugin.start(s)  # the campaign's own end: quiet_scheduler_off
    s.plugins[SCHEDULER_PLUGIN_NAME] = plugin
    assert quiet_scheduler_off(s) is True
    assert s.state() == before and SCHEDULER_PLUGIN_NAME not in s.plugins
    assert quiet_scheduler_off(s) is False and s.state() == before


TWO = """
[campaign]
name = "quiet"
duration_s = 2.0
controllers = ["gs-shif", "lqr"]
phases = [1.0]

[[faults]]
family = "rotor"
generate = "each"
actuators = ["rotor_2a"]
kinds = ["loss"]
magnitudes = [0.5]
"""


def test_a_dask_campaign_quiets_the_scheduler_and_workers_while_it_runs():
    """On a real (in-process) cluster: quiet from the campaign's preparation (registered
    twice, as ``vtolftc campaign`` then ``run_dask`` do) to its last row, every callback
    back on after it, the same rows as one process."""
    from distributed import Client, LocalCluster

    def sched(dask_scheduler):
        p = dask_scheduler.periodic_callbacks
        return (p["tick"].is_running(), p["monitor"].is_running(),
                SCHEDULER_PLUGIN_NAME in dask_scheduler.plugins)

    def worker(dask_worker):
        p = dask_worker.periodic_callbacks
        return (p["profile"].is_running(), p["monitor"].is_running(),
                p["memory_monitor"].callback_time)

    scen = expand(parse_spec(TWO))
    serial = {r["scenario_id"]: r["max_attitude_excursion_deg"]
              for r in map(execute.fly_scenario, scen)}
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster, \
            Client(cluster, set_as_default=False) as c:
        on = (c.run_on_scheduler(sched), set(c.run(worker).values()))
        assert on == ((True, True, False), {(True, True, 100.0)})
        execute.prepare_dask(c, scen)
        execute.prepare_dask(c, scen)
        got = {}
        for row in execute.run_dask(scen, c, tag="quiet"):
            assert c.run_on_scheduler(sched) == (False, False, True)
            assert set(c.run(worker).values()) == {(False, False, MEMORY_CHECK_MS)}
            got[row["scenario_id"]] = row["max_attitude_excursion_deg"]
        assert got == serial
        assert (c.run_on_scheduler(sched), set(c.run(worker).values())) == on
        # a campaign whose process dies before its end (no release): its client leaving
        # the scheduler starts the scheduler's callbacks again and unregisters the plugin
        with Client(cluster, set_as_default=False) as dying:
            execute.prepare_dask(dying, scen)
            assert c.run_on_scheduler(sched) == (False, False, True)
        deadline = time.monotonic() + 30
        while c.run_on_scheduler(sched) != on[0]:
            assert time.monotonic() < deadline, c.run_on_scheduler(sched)
            time.sleep(0.05)
