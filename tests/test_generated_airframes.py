"""Generated airframes as a test oracle (issue 22, item 6).

Hypothesis draws physically consistent dual-system VTOL airframes
(:func:`tests.support.airframes.airframe_documents`: 2-30 kg, 4/6/8 lift rotors, spans
1.5-5 m, hover thrust-to-weight 1.5-3). For each one the loader and the flyability check
either accept it or refuse it in one line; an accepted one goes through the cheapest synthesis
that gives a flyable schedule (paper method, GS-SHIF at two design points: hover and the
transition end, no random start, no SHIF, no mu, no report) and flies the nominal case 0
(takeoff to 30 m, front transition at t = 20 s, fixed-wing cruise) in-process.

Flown means: no crash, no quad-chute, the transition completes, and from the transition
command on the altitude stays within :data:`ALT_TOL_M` below its reference, its RMSE within
:data:`ALT_RMSE_TOL_M` and the final altitude within :data:`ALT_TOL_M` of the reference.

The autopilot's transition and cruise airspeeds (``VT_ARSP_TRANS``, ``FW_AIRSPD_TRIM``,
``FW_AIRSPD_MIN/MAX``) default to the airframe's own (its ``[airspeeds]`` or the loader's rule
from the wing); the test checks that the autopilot took them and sets nothing itself.

The run is derandomized (the same 30+ airframes every time, no shrinking, no example
database): a failure prints the airframe document (JSON), which
``airframe_from_dict(json.loads(text))`` loads again.
"""

from __future__ import annotations

import hashlib
import json
import math
import tempfile
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, assume, example, given, note, settings
from support.airframes import (
    MASS_RANGE_KG,
    N_LIFT_ROTORS,
    SPAN_RANGE_M,
    TW_RANGE,
    airframe_documents,
    hover_thrust_to_weight,
)

from vtolftc.airframe.loader import (
    DS1_PATH,
    Airframe,
    AirframeError,
    airframe_from_dict,
    hover_effectiveness,
)

N_EXAMPLES = 32
"""Generated airframes synthesised and flown by the slow test."""
ALT_TOL_M = 5.0
"""Largest altitude loss below the reference from the transition command on, and largest final
altitude error [m] (the campaigns' survival rule uses 5 m at the end)."""
ALT_RMSE_TOL_M = 2.0
"""Largest altitude RMSE from the transition command on [m] (DS-1 case 0: about 0.1 m)."""
FLIGHT_S = 40.0
"""Simulated flight time [s]: transition command at 20 s, VT_TRANS_TMOUT 15 s, then cruise."""

_FLOWN: set[str] = set()
"""Names (layout, mass to 0.1 kg, span to 0.01 m) already flown in this session: Hypothesis
mutates earlier examples, and a near-copy of an airframe would spend the CI budget on the same
aircraft, so the slow test rejects it (rejected draws do not count towards max_examples)."""


def _weak_pusher_ds1() -> dict[str, Any]:
    """DS-1 with 2 N pushers: cannot reach its wing-borne trim (an explicit example that the
    flyability check refuses, so the one-line refusal branch runs every time)."""
    doc = tomllib.loads(DS1_PATH.read_text())
    doc["airframe"]["name"] = "DS-1 with 2 N pushers"
    doc["pushers"]["max_thrust_N"] = 2.0
    return doc


def _load(doc: dict[str, Any]) -> Airframe:
    text = json.dumps(doc, sort_keys=True)
    return airframe_from_dict(doc, source=f"generated {doc['airframe']['name']}",
                              sha256=hashlib.sha256(text.encode()).hexdigest())


# ------------------------------------------------------------------------------------------
# the strategy itself (fast)
# ------------------------------------------------------------------------------------------


@settings(max_examples=150, derandomize=True, deadline=None, database=None)
@given(doc=airframe_documents())
def test_generated_documents_load_within_their_ranges(doc):
    note(json.dumps(doc))
    af = _load(doc)
    assert MASS_RANGE_KG[0] <= af.mass_kg <= MASS_RANGE_KG[1]
    assert SPAN_RANGE_M[0] - 1e-9 <= af.wing.span_m <= SPAN_RANGE_M[1] + 1e-9
    assert len(af.lift_rotors) in N_LIFT_ROTORS
    tw = hover_thrust_to_weight(doc)
    assert TW_RANGE[0] - 1e-9 <= tw <= TW_RANGE[1] + 1e-9
    assert math.isclose(sum(r.max_thrust_N for r in af.lift_rotors) / af.weight_N, tw)
    # the wing: S b = area, span^2 / S = aspect ratio, a plausible wing loading
    assert math.isclose(af.wing.area_m2, af.wing.span_m * af.wing.chord_m, rel_tol=1e-9)
    assert 4.0 <= af.wing.aspect_ratio <= 16.0
    assert 40.0 <= af.weight_N / af.wing.area_m2 <= 260.0
    # alternating spins: equal thrusts give no yaw moment, and no roll / pitch either at
    # the centroid of the rotors (yaw balanced, as many cw as ccw)
    B = hover_effectiveness(af)
    spins = [r.spin_axis[2] for r in af.lift_rotors]
    assert sum(s > 0 for s in spins) == sum(s < 0 for s in spins)
    assert abs(B[3].sum()) < 1e-9
    assert abs(B[1].sum()) < 1e-9  # mirror-symmetric in y
    # inertia of the mass distribution: Jz the largest, the triangle inequality strict
    jx, jy, jz = np.diag(af.inertia_kg_m2)
    assert jz > max(jx, jy) and jz < jx + jy
    # every actuator of the file is named, within HIL's 16 outputs
    assert af.n_actuators <= 16


# ------------------------------------------------------------------------------------------
# synthesis and nominal flight of generated airframes (slow)
# ------------------------------------------------------------------------------------------


def _cheap_gains(af: Airframe, out: Path) -> None:
    """GS-SHIF (paper method) at hover and the transition end, no random start; LQR."""
    from vtolftc.synthesis.baselines import lqr_design
    from vtolftc.synthesis.design import paper_points, run_designs
    from vtolftc.synthesis.pipeline import write_gain_files
    from vtolftc.synthesis.result import SynthesisResult

    pts = paper_points(af)
    sel = (pts[0], pts[-1])
    gs, sh = run_designs(af, n_starts=0, seed=0, points=sel, shif=False)
    for ax, designs in gs.items():
        assert [d.stable for d in designs] == [True, True], (ax, [d.label for d in designs])
    res = SynthesisResult(af, sel, gs, sh, lqr_design(af), settings={"n_starts": 0},
                          method="paper")
    write_gain_files(res, out)


def _fly(af: Airframe, gains_dir: Path) -> dict[str, Any]:
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    speeds = af.airspeeds
    assert speeds is not None

    def setup(ap: Any) -> None:  # the airframe's airspeeds, not DS-1's, by default
        assert ap.params.get("VT_ARSP_TRANS") == speeds.transition_end_m_s
        assert ap.params.get("FW_AIRSPD_TRIM") == speeds.cruise_m_s

    run = run_scenario(paper_scenario(0, FLIGHT_S, airframe=af), "gs-shif", airframe=af,
                       gains_dir=gains_dir, autopilot_setup=setup)
    m = dict(run.metrics)
    m["events"] = [text for _, kind, text in run.events if kind != "command"]
    return m


@pytest.mark.slow
@settings(max_examples=N_EXAMPLES, derandomize=True, deadline=None, database=None,
          phases=(Phase.explicit, Phase.generate),
          suppress_health_check=(HealthCheck.too_slow, HealthCheck.filter_too_much))
@given(doc=airframe_documents())
@example(doc=_weak_pusher_ds1())
def test_generated_airframes_synthesise_and_fly_the_nominal_transition(doc):
    """Each generated airframe is refused in one line or synthesised and flown (case 0)."""
    from vtolftc.firmware_sim.vehicle.flyable import check_flyable

    name = doc["airframe"]["name"]
    # near-copies of an airframe already flown do not count; a failing one is not recorded,
    # so that hypothesis' replay of a failure reaches the failure again
    assume(name not in _FLOWN)
    note("airframe document (airframe_from_dict(json.loads(...))): " + json.dumps(doc))
    try:
        af = _load(doc)
        check_flyable(af)
    except AirframeError as exc:
        text = str(exc)
        assert "\n" not in text and text.startswith("generated "), text
        print(f"REFUSED {doc['airframe']['name']}: {text}")
        _FLOWN.add(name)
        return
    with tempfile.TemporaryDirectory(prefix="vtolftc-gen-") as tmp:
        try:
            _cheap_gains(af, Path(tmp))
        except AirframeError as exc:
            assert "\n" not in str(exc), str(exc)
            print(f"REFUSED (synthesis) {af.name}: {exc}")
            _FLOWN.add(name)
            return
        m = _fly(af, Path(tmp))
    speeds = af.airspeeds
    summary = {k: m[k] for k in ("crashed", "quad_chute", "transition_complete_s",
                                 "max_altitude_lost_m", "rmse_altitude_m",
                                 "final_altitude_error_m", "final_airspeed_m_s",
                                 "max_attitude_excursion_deg")}
    note(f"stall {speeds.stall_m_s:.2f} m/s, transition end {speeds.transition_end_m_s:.2f}, "
         f"cruise {speeds.cruise_m_s:.2f}; metrics {summary}; events {m['events']}")
    print(f"FLEW {af.name}: {summary}")
    assert not m["crashed"]
    assert not m["quad_chute"]
    assert m["transition_complete_s"] is not None
    assert m["max_altitude_lost_m"] <= ALT_TOL_M
    assert m["rmse_altitude_m"] <= ALT_RMSE_TOL_M
    assert abs(m["final_altitude_error_m"]) <= ALT_TOL_M
    _FLOWN.add(name)
