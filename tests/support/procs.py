"""The processes tests start: their live process trees, read through psutil (one home for
every test that needs the live descendants of a process it started), how the real-time
SITL tests ask for scheduling priority, and the command lines a SITL run would start its
programs with (without starting them)."""

from __future__ import annotations

from typing import Any

import psutil

__all__ = ["RT_PRIORITY", "descendants", "sitl_command_lines"]

RT_PRIORITY = ["--rt-priority", "10"]
"""Extra arguments of both SITL processes in the real-time tests: SCHED_FIFO where permitted
(root, as CI; :mod:`vtolftc.runners.processes.priority`). Beside CPU burners on 2 cores an
ordinary process was runnable yet given no CPU for 0.66-1.41 s, longer than the 0.5 s HIL-loss
and output-watchdog tolerances those tests fly with."""


def descendants(pid: int) -> set[int]:
    """Every live descendant of ``pid`` (children, their children, ...); empty when ``pid``
    is gone."""
    try:
        return {c.pid for c in psutil.Process(pid).children(recursive=True)}
    except psutil.NoSuchProcess:
        return set()


def sitl_command_lines(monkeypatch: Any, cfg: Any) -> dict[str, list[str]]:
    """The arguments :class:`vtolftc.runners.sitl.SitlRun` would start the vehicle and the
    autopilot programs with for ``cfg`` (a ``SitlConfig``): ``_spawn`` records them and the
    run stops at its ground station, so no process is started."""
    import pytest

    from vtolftc.runners.sitl import SitlRun

    class SpawnedError(Exception):
        pass

    class FakeStation:
        def __init__(self, url: str) -> None:
            pass

        def add_listener(self, fn: Any) -> None:  # start() reaches this once both are spawned
            raise SpawnedError

    monkeypatch.setattr("vtolftc.runners.sitl.GroundStation", FakeStation)
    run = SitlRun(cfg)
    argv: dict[str, list[str]] = {}
    monkeypatch.setattr(run, "_spawn", lambda name, args: argv.__setitem__(name, args))
    with pytest.raises(SpawnedError):
        run.start()
    assert set(argv) == {"vehicle", "autopilot"}
    return argv
