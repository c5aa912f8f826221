"""Validation between design points (``synthesis/validation.py``): the margins against
``control.stability_margins`` on textbook loops, the gains as the autopilot flies them, the
grid is 4x the design grid, and a schedule destabilised between its design points is
flagged there (and only there)."""

from __future__ import annotations

import copy
import itertools
import json
import math
from importlib import resources

import control as ct
import numpy as np
import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.firmware_sim.autopilot.schedule import GainSchedule
from vtolftc.synthesis.loops import PARAM_NAMES
from vtolftc.synthesis.validation import (
    FlownSchedule,
    cell_bounds,
    dense_grid,
    design_grid,
    loop_margins_classical,
    validate_schedule,
)

S = ct.tf("s")
TEXTBOOK = {
    "third-order lag": 4 / (S + 1) ** 3,
    "type 1": 10 / (S * (S + 1) * (S + 5)),
    "conditionally stable": 40 * (S + 1) ** 2 / (S ** 3 * (S + 10)),
    "lead": 2 * (S + 0.5) / (S ** 2 * (0.05 * S + 1)),
}


def _shipped(name: str = "gs-shif.json") -> dict:
    p = resources.files("vtolftc.firmware_sim.autopilot") / "gains" / name
    return json.loads(p.read_text())


@pytest.mark.parametrize("name", list(TEXTBOOK))
def test_margins_match_python_control(name: str) -> None:
    L = TEXTBOOK[name]
    gm, pm, _, wg, wc, _ = ct.stability_margins(L)
    gms, pms, _, _w180, wcs, _ = ct.stability_margins(L, returnall=True)
    m = loop_margins_classical(lambda w: L(1j * w))
    if math.isinf(gm):
        assert math.isinf(m.gain_margin)
    else:
        assert m.gain_margin == pytest.approx(gm, rel=1e-6)
        assert m.phase_crossover_rad_s == pytest.approx(wg, rel=1e-6)
    assert m.phase_margin_deg == pytest.approx(pm, abs=1e-5)
    assert m.gain_crossover_rad_s == pytest.approx(wc, rel=1e-6)
    # upper / lower gain margins and the delay margin from all of python-control's crossings
    ups = [g for g in gms if g > 1]
    los = [g for g in gms if g < 1]
    assert m.gain_margin_upper == pytest.approx(min(ups) if ups else math.inf, rel=1e-6)
    assert m.gain_margin_lower == pytest.approx(max(los) if los else 0.0, rel=1e-6)
    dm = min(math.radians(p % 360) / w for p, w in zip(pms, wcs, strict=True))
    assert m.delay_margin_s == pytest.approx(dm, rel=1e-6)


def test_delay_margin_is_the_delay_that_destabilises() -> None:
    """An independent check: the loop with the delay margin (less 2 %) stable, (plus 2 %)
    unstable (Pade of order 10)."""
    L = TEXTBOOK["type 1"]
    dm = loop_margins_classical(lambda w: L(1j * w)).delay_margin_s
    for k, stable in ((0.98, True), (1.02, False)):
        Ld = L * ct.tf(*ct.pade(k * dm, 10))
        poles = ct.feedback(Ld, 1).poles()
        assert bool(np.all(poles.real < 0)) is stable


def test_third_order_lag_closed_form() -> None:
    """4 / (s + 1)^3: phase -180 deg at w = sqrt(3), |L| = 4 / 8: GM = 2."""
    m = loop_margins_classical(lambda w: 4 / (1j * w + 1) ** 3)
    assert m.gain_margin == pytest.approx(2.0, rel=1e-9)
    assert m.phase_crossover_rad_s == pytest.approx(math.sqrt(3), rel=1e-9)
    assert m.gain_margin_upper_db == pytest.approx(20 * math.log10(2), rel=1e-9)


def test_gains_are_interpolated_as_the_autopilot_flies_them() -> None:
    doc = _shipped()
    flown = FlownSchedule(doc)
    gs = GainSchedule.from_dict(doc)
    bps = doc["airspeed_breakpoints_m_s"]
    vs = np.concatenate([bps, np.random.default_rng(3).uniform(-2, 25, 200),
                         [float("nan"), 1e-12, 17.999999]])
    for v in vs:
        want = gs.gains_at(float(v))
        for ax in ("roll", "pitch", "yaw"):
            got = flown.gains_at(ax, float(v))
            for k in PARAM_NAMES:
                assert got[k] == getattr(want[ax], k)  # bit for bit


def test_dense_grid_is_four_times_the_design_grid() -> None:
    pts = design_grid(_shipped())
    assert len(pts) == 7
    g = dense_grid(pts)
    assert len(g) == 4 * (len(pts) - 1) + 1 == 25
    vs = [p.airspeed_m_s for p in g]
    assert vs == sorted(vs)
    assert {p.airspeed_m_s for p in pts} <= set(vs)
    for a, b in itertools.pairwise(pts):   # 4 equal intervals in each
        inside = [v for v in vs if a.airspeed_m_s <= v <= b.airspeed_m_s]
        assert len(inside) == 5
        assert np.diff(inside) == pytest.approx([(b.airspeed_m_s - a.airspeed_m_s) / 4] * 4)
    lo, hi = cell_bounds(vs)   # the cells tile the range
    assert lo[0] == vs[0] and hi[-1] == vs[-1]
    assert lo[1:] == hi[:-1]
    assert all(a <= v <= b for a, v, b in zip(lo, vs, hi, strict=True))


def test_design_grid_without_metadata_is_the_breakpoints() -> None:
    doc = _shipped()
    del doc["design_points"]
    pts = design_grid(doc)
    assert [p.airspeed_m_s for p in pts] == doc["airspeed_breakpoints_m_s"]
    assert pts[1].v_min_m_s == 0.5 and pts[1].v_max_m_s == 2.5


def test_a_schedule_destabilised_between_design_points_is_flagged() -> None:
    """Gains x50 at a breakpoint inserted halfway between design points 4 and 5 (7 and
    10 m/s for DS-1): the 4x grid point there is unstable and flagged as a failure between
    points; the design points either side are unchanged."""
    af = load_airframe()
    doc = _shipped()
    bad = copy.deepcopy(doc)
    bps = bad["airspeed_breakpoints_m_s"]
    i = bps.index(7.0)
    bps.insert(i + 1, 8.5)
    for ax in ("roll", "pitch", "yaw"):
        for k in PARAM_NAMES:
            t = bad["axes"][ax][k]
            mid = 0.5 * (t[i] + t[i + 1])
            t.insert(i + 1, mid if k == "tf_rate_s" else 50.0 * mid)
    GainSchedule.from_dict(bad)  # still a valid file
    kw = dict(axes=("pitch",), airspeeds_m_s=[7.0, 8.5, 10.0], mu=False, certificate=False)
    res = validate_schedule(af, bad, **kw)
    flagged = {r.airspeed_m_s: r for r in res.failures}
    assert set(flagged) == {8.5}
    r = flagged[8.5]
    assert not r.design_point and r in res.failures_between
    assert not r.stable and "unstable" in r.failures[0]
    assert res.summary()["pitch"]["failures_between"] == 1
    # the same slice of the shipped schedule passes
    ok = validate_schedule(af, doc, **kw)
    assert ok.failures == []
    assert all(r.stable for r in ok.rows)


def test_destabilised_gains_fail_the_mixed_mu_cell_bound() -> None:
    """The certificate part sees gains that only destabilise at the cell's end: gains x50
    at the next breakpoint leave the grid point itself at the shipped gains but the cell's
    end with huge ones, and the cell bound is not below 1."""
    af = load_airframe()
    bad = copy.deepcopy(_shipped())
    bps = bad["airspeed_breakpoints_m_s"]
    i = bps.index(7.0)
    bps.insert(i + 1, 7.375)  # the end of 7 m/s's cell (grid spacing 0.75 m/s)
    for ax in ("roll", "pitch", "yaw"):
        for k in PARAM_NAMES:
            t = bad["axes"][ax][k]
            t.insert(i + 1, t[i] if k == "tf_rate_s" else 50.0 * t[i])
    res = validate_schedule(af, bad, axes=("pitch",), airspeeds_m_s=[7.0], mu=False)
    (r,) = res.rows
    assert r.stable and r.mixed_mu_upper is not None and r.mixed_mu_upper < 1.0
    assert r.mixed_mu_ends is not None and not r.mixed_mu_ends[1] < 1.0
    assert any("mixed mu over the cell" in f for f in r.failures)


def test_validation_json_round_trips(tmp_path) -> None:  # type: ignore[no-untyped-def]
    af = load_airframe()
    res = validate_schedule(af, _shipped(), axes=("roll",), airspeeds_m_s=[4.0, 4.75])
    p = res.write(tmp_path / "validation.json")
    d = json.loads(p.read_text())
    assert d["density"] == 4 and len(d["grid_m_s"]) == 25
    assert [r["airspeed_m_s"] for r in d["rows"]] == [4.0, 4.75]
    row = d["rows"][1]
    assert row["design_point"] is False
    assert row["mu_rs"] > 0 and row["mixed_mu_upper"] > 0
    assert row["margins"]["delay_margin_s"] > 0


def test_synth_surface_rejects_bad_input(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    from vtolftc.cli.main import run

    for argv, word in ((["--method", "surface", "--degree", "9"], "--degree"),
                       (["--method", "surface", "--degree", "-1"], "--degree"),
                       (["--method", "surface", "--max-iter", "0"], "--max-iter"),
                       (["--degree", "2"], "--method surface only"),
                       (["--method", "paper", "--max-iter", "3"], "--method surface only")):
        assert run(["synth", *argv, "--out", str(tmp_path)]) == 2
        err = capsys.readouterr().err
        assert word in err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_validation_report_plots_every_gain(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from vtolftc.synthesis.validation_report import surface_curves, write_validation_report

    af = load_airframe()
    doc = _shipped()
    res = validate_schedule(af, doc, axes=("yaw",), airspeeds_m_s=[0.0, 0.25],
                            certificate=False)
    md = write_validation_report(doc, res, tmp_path).read_text()
    for ax in ("roll", "pitch", "yaw"):
        svg = (tmp_path / f"validation-gains-{ax}.svg").read_text()
        for k in PARAM_NAMES:
            assert f"{ax} {k}" in svg   # one panel per gain, titled
        assert f"validation-gains-{ax}.svg" in md
    assert (tmp_path / "validation-checks.svg").stat().st_size > 1000
    assert "| yaw | 0.25 |" in md
    assert surface_curves(doc, "roll", [1.0]) is None  # a point design has no surface


@pytest.mark.slow
def test_synth_surface_cli_writes_a_gains_dir_the_autopilot_flies(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Fast settings (degree 1, no random start, one iteration, no mu, no report)."""
    from vtolftc.cli.main import run
    from vtolftc.firmware_sim.autopilot.attitude import make_controller

    af = load_airframe()
    out = tmp_path / "gains"
    assert run(["synth", "--method", "surface", "--degree", "1", "--starts", "0",
                "--max-iter", "1", "--no-mu", "--no-report", "--quiet",
                "--out", str(out)]) == 0
    assert {"gs-shif.json", "shif.json", "lqr.json", "surfaces.json",
            "validation.json"} <= {p.name for p in out.iterdir()}
    surf = json.loads((out / "surfaces.json").read_text())["axes"]
    for name in ("gs-shif", "shif", "lqr"):
        ctl = make_controller(name, out, airframe_name=af.name, airframe_sha256=af.sha256)
        assert ctl.name == name
    gs = GainSchedule.load(out / "gs-shif.json")
    assert len(gs.breakpoints_m_s) == 13   # the surface grid
    from vtolftc.synthesis.validation_report import surface_curves

    doc = json.loads((out / "gs-shif.json").read_text())
    for ax in ("roll", "pitch", "yaw"):
        assert surf[ax]["degree"] == 1
        assert surf[ax]["surface_objective"] <= surf[ax]["constant_objective"]
        curves = surface_curves(doc, ax, list(gs.breakpoints_m_s))
        assert curves is not None and set(curves) == set(PARAM_NAMES)
    val = json.loads((out / "validation.json").read_text())
    assert len(val["grid_m_s"]) == 4 * 12 + 1
    assert len(val["rows"]) == 3 * 49


def test_synthesis_report_links_the_gain_plots(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The robust / paper report gets every GS-SHIF gain against airspeed."""
    from vtolftc.synthesis.pipeline import _gain_plots

    gains = tmp_path / "gs-shif.json"
    gains.write_text(json.dumps(_shipped()))
    readme = tmp_path / "report" / "README.md"
    readme.parent.mkdir()
    readme.write_text("# report\n")
    _gain_plots(gains, readme)
    text = readme.read_text()
    assert text.startswith("# report\n")
    for ax in ("roll", "pitch", "yaw"):
        assert f"(validation-gains-{ax}.svg)" in text
        assert (readme.parent / f"validation-gains-{ax}.svg").is_file()


def test_constant_gains_make_the_cell_bound_the_proved_bound() -> None:
    """With SHIF's constant gains nothing moves across a cell but the plant, which the LFT
    covers exactly: the bounds at the cell's ends (same family, same gains) are the centre's
    and the cell bound adds nothing."""
    af = load_airframe()
    (r,) = validate_schedule(af, _shipped("shif.json"), axes=("roll",), airspeeds_m_s=[8.5],
                             mu=False).rows
    assert r.mixed_mu_ends is not None and r.mixed_mu_upper is not None
    assert r.mixed_mu_ends == pytest.approx((r.mixed_mu_upper, r.mixed_mu_upper), rel=2e-3)
    assert r.mixed_mu_cell == pytest.approx(r.mixed_mu_upper, rel=2e-3)
    assert r.cell_m_s == (8.125, 8.875)
