"""Shared fixtures: the DS-1 airframe and its trims are computed once per test session."""

from __future__ import annotations

import json

import pytest

from vtolftc.airframe.loader import Airframe, load_airframe


@pytest.fixture(scope="session")
def ds1() -> Airframe:
    return load_airframe()


@pytest.fixture(scope="session")
def hover_trim(ds1):
    from vtolftc.firmware_sim.vehicle.trim import trim_hover

    return trim_hover(ds1, altitude_m=30.0)


@pytest.fixture(scope="session")
def cruise_trim(ds1):
    from vtolftc.firmware_sim.vehicle.trim import trim_level_flight

    return trim_level_flight(ds1, 18.0, altitude_m=30.0)


@pytest.fixture(scope="session")
def hand_gains(tmp_path_factory, ds1):
    """A gains directory with hand-picked gains in the shipped formats (gs-shif with two
    equal breakpoints, shif, lqr), independent of the synthesis output, for tests of the
    flight logic that must not move when the synthesis changes."""
    d = tmp_path_factory.mktemp("hand_gains")
    base = {"roll": (5.0, 14.0, 14.0, 0.3, 0.02), "pitch": (5.0, 12.0, 12.0, 0.25, 0.02),
            "yaw": (2.5, 14.0, 7.0, 0.0, 0.02)}
    fields = ("kp_angle", "kp_rate", "ki_rate", "kd_rate", "tf_rate_s")
    af = {"name": ds1.name, "sha256": ds1.sha256}
    for name, bp in (("gs-shif", [0.0, 13.0]), ("shif", [0.0])):
        axes = {ax: {f: [v] * len(bp) for f, v in zip(fields, g, strict=True)}
                for ax, g in base.items()}
        (d / f"{name}.json").write_text(json.dumps({
            "format": "vtolftc-gain-schedule/1", "controller": name, "airframe": af,
            "airspeed_breakpoints_m_s": bp, "axes": axes}))
    (d / "lqr.json").write_text(json.dumps({
        "format": "vtolftc-lqr-gains/1", "controller": "lqr", "airframe": af,
        "airspeed_breakpoints_m_s": [0.0],
        "axes": {ax: {"k_int": [g[0] * g[2] * 0.5], "k_angle": [g[0] * g[1]],
                      "k_rate": [g[1]]} for ax, g in base.items()}}))
    return d
