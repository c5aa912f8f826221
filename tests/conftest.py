"""Shared fixtures: the DS-1 airframe and its trims are computed once per test session."""

from __future__ import annotations

import pytest

from airframe.loader import Airframe, load_airframe


@pytest.fixture(scope="session")
def ds1() -> Airframe:
    return load_airframe()


@pytest.fixture(scope="session")
def hover_trim(ds1):
    from firmware_sim.vehicle.trim import trim_hover

    return trim_hover(ds1, altitude_m=30.0)


@pytest.fixture(scope="session")
def cruise_trim(ds1):
    from firmware_sim.vehicle.trim import trim_level_flight

    return trim_level_flight(ds1, 18.0, altitude_m=30.0)
