"""The autopilot process's loop runs an observer's deferred work (``idle_work``, the SITL
rerun recorder's sends in pieces) only while it waits with nothing to step on: piece by piece
until the observer says it is done (then once per wait, a no-op: no spinning on it), and not
while a state is there (the held state at t = 0 here)."""

from __future__ import annotations

from types import SimpleNamespace

from support.memory_link import CaptureTransport

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.autopilot.autopilot import Autopilot
from vtolftc.firmware_sim.autopilot.process import AutopilotProcess
from vtolftc.protocols import Link
from vtolftc.protocols.failure_units import ActuatorTable


class Deferred:
    """An observer with ``pieces`` pieces of deferred work (``idle_work`` with none left is a
    cheap no-op, as the recorder's; called more than 1000 times in a row without a piece,
    the loop spins on it: that raises)."""

    def __init__(self, pieces: int) -> None:
        self.left = pieces
        self.calls = 0
        self.idle_calls = 0

    def on_start(self, info):
        pass

    def on_sample(self, sample):
        pass

    def on_event(self, time_usec, kind, text):
        pass

    def on_finish(self, metrics):
        pass

    def idle_work(self) -> bool:
        if self.left == 0:
            self.idle_calls += 1
            if self.idle_calls > 1000:
                raise RuntimeError("the loop spins on idle_work")
            return False
        self.idle_calls = 0
        self.calls += 1
        self.left -= 1
        return self.left > 0


def _run(observer: Deferred, state_after: int | None) -> list[tuple[float, int]]:
    """The loop for 0.3 s of wall time with no vehicle; from ``state_after`` pieces on (if
    given) a state at t = 0 is there to step on, held (``hold_ms`` 0). Returns the HIL
    link's drains: (timeout [s], pieces done before it)."""
    af = load_airframe()
    link = Link(CaptureTransport(), system_id=1, component_id=1)
    proc = AutopilotProcess(Autopilot(af), link, [], observers=[observer], hold_ms=0,
                            actuators=ActuatorTable.from_names(af.actuator_names),
                            max_wall_s=0.3)
    drains: list[tuple[float, int]] = []
    drain = proc.hil.drain
    proc.hil.drain = lambda timeout: (drains.append((timeout, observer.calls)),
                                      drain(timeout))[1]
    if state_after is not None:
        nav = SimpleNamespace(time_usec=0)
        proc.hil.peek = lambda: nav if observer.calls >= state_after else None
    try:
        proc._loop(proc.hil, proc.gcs, proc.ap)
    finally:
        proc.gcs.close()
        proc.hil.link.close()
    return drains


def test_idle_work_runs_piece_by_piece_until_done_while_waiting():
    obs = Deferred(7)
    drains = _run(obs, None)
    assert obs.calls == 7 and obs.left == 0  # every piece
    # all in the first wait, each followed by a look at the link, before it blocks
    assert drains[:7] == [(0.0, k) for k in range(1, 7)] + [(0.01, 7)], drains[:8]


def test_no_idle_work_while_a_state_is_there():
    obs = Deferred(7)
    _run(obs, 3)
    assert obs.calls == 3 and obs.left == 4
