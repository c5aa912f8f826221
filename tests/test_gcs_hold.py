"""The simulation hold of the ground-station endpoint (gcs_hold.SimulationHold)."""

from __future__ import annotations

from vtolftc.firmware_sim.autopilot.gcs_hold import SIM_HOLD_PARAM, SimulationHold
from vtolftc.firmware_sim.autopilot.interface import ParameterStore


def test_hold_time_from_the_parameter_and_never_without_lockstep():
    store = ParameterStore()
    hold = SimulationHold(store, lockstep=True, hold_ms=1500)
    assert int(store.get(SIM_HOLD_PARAM)) == 1500
    assert hold.hold_usec() == 1_500_000
    store.set(SIM_HOLD_PARAM, -1)
    assert hold.hold_usec() is None
    assert SimulationHold(ParameterStore(), lockstep=False, hold_ms=1500).hold_usec() is None


def test_announced_at_once_then_once_a_second_until_time_moves_on():
    hold = SimulationHold(ParameterStore(), lockstep=True, hold_ms=2000)
    assert hold.due(10.0) is None                  # not held yet
    assert hold.announce(2_000_400) is True         # control thread: held at 2000 ms
    assert hold.announce(2_000_900) is False        # same ms: no news
    assert hold.due(10.0) == 2000                   # worker: at once
    assert hold.due(10.5) is None
    assert hold.due(11.0) == 2000                   # then at 1 Hz
    hold.notice_ms = None                           # a step ran
    hold.stepped()
    assert hold.due(11.2) is None
    assert hold.announce(3_000_000) is True
    assert hold.due(11.3) == 3000                   # a new hold goes out at once
