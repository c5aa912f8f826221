"""The processes tests start: their live process trees, read through psutil (one home for
every test that needs the live descendants of a process it started), how the real-time
SITL tests ask for scheduling priority, the command lines a SITL run would start its
programs with (without starting them), and a child process with a zenoh link whose threads a
test inspects after a scheduling call."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

import psutil

__all__ = ["RT_PRIORITY", "ZenohProbe", "descendants", "sitl_command_lines",
           "zenoh_probe"]

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


_ZENOH_PROBE = """
import os, sys, time
from vtolftc.protocols.zenoh_transport import ZenohTransport
from vtolftc.runners.processes.{module} import {function}
port = int(sys.argv[1])
up = ZenohTransport("ds1", "hil", "up", listen=[f"tcp/127.0.0.1:{{port}}"], receive="channel")
down = ZenohTransport("ds1", "hil", "down", connect=[f"tcp/127.0.0.1:{{port}}"],
                      receive="channel")
deadline = time.monotonic() + 20.0
while not (up.ready() and down.ready()) and time.monotonic() < deadline:
    time.sleep(0.01)
ok = {function}({args}, "probe", sys.stdout{extra})
for tid in sorted(int(t) for t in os.listdir("/proc/self/task")):
    name = open(f"/proc/self/task/{{tid}}/comm").read().strip()
    print("thread", name, {report})
up.send_bytes(b"after")   # the link still works after the call
got = []
while not got and time.monotonic() < deadline:
    got = down.recv_datagrams(1.0)
print("got", got)
up.close(); down.close()
print("ok", ok)
"""


class ZenohProbe:
    """What :func:`zenoh_probe`'s child printed: its lines, and per thread (name, *fields).

    ``zenoh`` holds zenoh's runtime threads (named ``rx``/``tx``/``app``/``acc``/``net``-N),
    ``others`` the rest; ``applied`` is the scheduling call's return value and ``linked``
    whether a sample crossed the link after it."""

    def __init__(self, lines: list[str]) -> None:
        self.lines = lines
        self.threads = [ln.split()[1:] for ln in lines if ln.startswith("thread ")]
        self.zenoh = [t for t in self.threads
                      if t[0].split("-")[0] in ("rx", "tx", "app", "acc", "net")]
        self.others = [t for t in self.threads if t not in self.zenoh]
        self.applied = lines[-1] == "ok True"
        self.linked = "got [b'after']" in lines


def zenoh_probe(call: str, report: str) -> ZenohProbe:
    """Start a child process with a zenoh link to itself (two transports on a free loopback
    TCP port), make one scheduling call once the link is up, print each thread's name and
    ``report`` (an expression of ``tid``), send a sample through the link, and end.

    Parameters
    ----------
    call : str
        ``"priority.apply_rt_priority(7)"`` or ``"affinity.apply_cpu(1, 0)"``: the module of
        :mod:`vtolftc.runners.processes`, its function and its arguments besides ``who`` and
        ``log`` (the first before them, the rest after).
    report : str
        What to print per thread, e.g. ``"*sorted(os.sched_getaffinity(tid))"``.
    """
    from vtolftc.protocols.netutil import free_tcp_port

    target, _, rest = call.partition("(")
    module, function = target.split(".")
    first, _, extra = rest.rstrip(")").partition(",")
    code = _ZENOH_PROBE.format(module=module, function=function, args=first.strip(),
                               extra=f", {extra.strip()}" if extra else "", report=report)
    out = subprocess.run([sys.executable, "-c", code, str(free_tcp_port())],
                         capture_output=True, text=True, timeout=90, check=True).stdout
    return ZenohProbe(out.splitlines())
