"""The real stages of ``vtolftc certify`` and the two profiles.

Every stage reads the airframe file named by the context and nothing DS-1 specific: the trim
airspeeds are fractions of the airframe's stall speed, the synthesis is ``vtolftc synth
--method robust`` on the file, the certificate runs on the gain schedule it wrote, the
campaign's fault families are actuator groups of the file (``lift_rotors``, ``surfaces``,
``pushers``) and the SITL mission flies the file with those gains.

Gates (each a one-line message in the record's ``gate_failures``; the command exits 1):

- trim: hover and a wing-borne trim exist;
- synthesis: every GS-SHIF design point is nominally stable;
- certificate: mixed mu upper bound < 1 (robust stability over the real parameter box
  airspeed x loss of effectiveness) at every claimed axis-point (the profile's
  ``certificate_claim``: every design point of every axis, the project's claim for DS-1);
- campaign: GS-SHIF survives 100 % of the scenarios the recoverability oracle calls
  recoverable among single lift-rotor losses (family ``rotor-off``) at hover and
  mid-transition, and >= 90 % of the recoverable double losses (``two-rotors-off``) at the
  same two phases (the cruise losses are flown and reported, not gated, as issue 22 asks); a
  scenario the oracle could not judge fails the gate; a gate with no recoverable scenario
  holds vacuously and the record's ``notes`` say so (a 4-rotor quadplane: no lift-rotor loss
  in hover leaves a trim);
- SITL: the mission reaches every item and lands (below 0.5 m) within 5 m of home.
"""

from __future__ import annotations

import hashlib
import json
import math
import shlex
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from vtolftc.base.errors import UsageError
from vtolftc.runners.certify.pipeline import Stage, StageContext, StageError, code_digest

__all__ = ["GATE_PHASES", "PROFILES", "SINGLE_PHASES", "default_stages"]

GATE_PHASES = ("hover", "transition")
"""Phases whose recoverable single and double lift-rotor losses the campaign gates count
(hover and mid-transition, issue 22); the other phases flown are reported only."""
SINGLE_PHASES = GATE_PHASES
"""Phases where every recoverable single lift-rotor loss must be survived."""
SINGLE_MIN = 1.0
DOUBLE_MIN = 0.9
LAND_RADIUS_M = 5.0

_FULL_FAMILIES = (
    ("rotor-off", "each", "lift_rotors", ("off",), None),
    ("two-rotors-off", "subsets", "lift_rotors", ("off",), 2),
    ("surface", "each", "surfaces", ("off", "stuck"), None),
    ("pusher", "each", "pushers", ("off", "stuck"), None),
)

PROFILES: dict[str, dict[str, Any]] = {
    "full": {
        "synth_starts": 2, "synth_mu": True, "synth_report": True,
        "certificate_axes": ["roll", "pitch", "yaw"], "certificate_points": "all",
        "certificate_grid_n": 41,
        "certificate_margin": True, "certificate_claim": "all",
        "campaign_families": [[f[0], f[1], f[2], list(f[3]), f[4]] for f in _FULL_FAMILIES],
        "campaign_phases": ["hover", "transition", "cruise"],
        "campaign_winds": ["calm", "crosswind-gust"], "campaign_duration_s": 60.0,
        "trim_stall_fractions": [0.3, 0.55, 0.8, 1.0, 1.4],
    },
    "quick": {
        "synth_starts": 0, "synth_mu": False, "synth_report": False,
        "certificate_axes": ["roll"], "certificate_points": "ends+middle",
        "certificate_grid_n": 21,
        "certificate_margin": False, "certificate_claim": "all",
        "campaign_families": [["rotor-off", "each", "lift_rotors", ["off"], None]],
        "campaign_phases": ["hover", "transition"],
        "campaign_winds": ["calm"], "campaign_duration_s": 40.0,
        "trim_stall_fractions": [0.5, 1.0, 1.4],
    },
    "gates": {
        "synth_starts": 2, "synth_mu": False, "synth_report": False,
        "certificate_axes": ["roll"], "certificate_points": "ends+middle",
        "certificate_grid_n": 21,
        "certificate_margin": False, "certificate_claim": "all",
        "campaign_families": [[f[0], f[1], f[2], list(f[3]), f[4]] for f in _FULL_FAMILIES[:2]],
        "campaign_phases": list(GATE_PHASES),
        "campaign_winds": ["calm"], "campaign_duration_s": 40.0,
        "trim_stall_fractions": [0.5, 1.0, 1.4],
    },
}
"""``full``: the certification (issue 22). ``quick``: the same chain on a slice (one tune
start, no lumped mu, no synthesis report, the roll certificate at the first, middle and
last design points, single lift rotors off at
hover and mid-transition in calm air, 40 s flights), for tests. ``gates``: the full
profile's synthesis (the same tune starts, so the same gains; without the lumped mu and the
synthesis report, which only analyse) and the campaign families its gates count (every single
and double lift-rotor loss at hover and mid-transition), calm, 40 s flights, with the quick
profile's certificate: the gates of issue 22 at a fraction of the full profile's time."""

_WINDS = {
    "calm": '[[wind]]\nname = "calm"\n',
    "crosswind-gust": ('[[wind]]\nname = "crosswind-gust"\nsteady_ned_m_s = [0.0, 4.0, 0.0]\n'
                       'gusts = [{ after_fault_s = 1.0, duration_s = 3.0, '
                       'amplitude_ned_m_s = [0.0, 3.0, -1.0] }]\n'),
}


def _load(ctx: StageContext) -> Any:
    from vtolftc.airframe.loader import load_airframe

    return load_airframe(ctx.airframe_path)


def _file_sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# --------------------------------------------------------------------------------------------
# trim
# --------------------------------------------------------------------------------------------

def stage_trim(ctx: StageContext) -> dict[str, Any]:
    """Trim table at 0 m/s and at the profile's fractions of the stall speed."""
    from vtolftc.firmware_sim.vehicle.trim import trim_table

    af = _load(ctx)
    vs = af.stall_speed_m_s()
    speeds = [0.0] + [round(f * vs, 2) for f in ctx.profile["trim_stall_fractions"]]
    rows = []
    for V, mode, tp, note in trim_table(af, speeds):
        r: dict[str, Any] = {"airspeed_m_s": V, "mode": mode, "feasible": tp is not None}
        if tp is None:
            r["note"] = note
        else:
            r.update(pitch_deg=math.degrees(tp.pitch_rad),
                     elevator_deg=math.degrees(tp.elevator_rad),
                     pusher_pct=100 * tp.pusher_thrust_fraction,
                     rotor_lift_share_pct=100 * tp.rotor_lift_share,
                     CL=tp.lift_coefficient)
        rows.append(r)
    fails = []
    if not any(r["feasible"] and r["mode"] == "hover" for r in rows):
        fails.append("trim: no hover trim")
    if not any(r["feasible"] and r["mode"] == "wing" for r in rows):
        fails.append("trim: no wing-borne trim at the profile's airspeeds")
    return {"verdict": "fail" if fails else "pass", "stall_speed_m_s": vs, "rows": rows,
            "airframe": af.name, "gate_failures": fails}


# --------------------------------------------------------------------------------------------
# synthesis
# --------------------------------------------------------------------------------------------

def stage_synth(ctx: StageContext) -> dict[str, Any]:
    """``vtolftc synth --method robust`` on the airframe into ``OUT/synth``."""
    from vtolftc.synthesis.models import AXES
    from vtolftc.synthesis.pipeline import run_synthesis

    af = _load(ctx)
    out = ctx.stage_dir("synth")
    p = ctx.profile
    try:
        res = run_synthesis(af, out, n_starts=int(p["synth_starts"]),
                            jobs=max(1, min(2, ctx.jobs or 2)), seed=0,
                            mu=bool(p["synth_mu"]), report=bool(p["synth_report"]),
                            method="robust")
    except ValueError as exc:  # e.g. a bound or start the airframe's physics does not fit
        raise StageError(f"robust synthesis refused the airframe: {exc}") from None
    points = [{"number": q.number, "airspeed_m_s": q.airspeed_m_s, "v_min_m_s": q.v_min_m_s,
               "v_max_m_s": q.v_max_m_s} for q in res.points]
    designs = {ax: [{"label": d.label, "stable": bool(d.stable),
                     "gamma": float(d.norms["gamma"])} for d in res.gs[ax]] for ax in AXES}
    unstable = [f"{ax} {d['label']}" for ax in AXES for d in designs[ax] if not d["stable"]]
    fails = [f"synthesis: nominally unstable GS-SHIF design(s): {', '.join(unstable)}"] \
        if unstable else []
    gains = {k: _file_sha(out / f"{k}.json") for k in ("gs-shif", "shif", "lqr")}
    return {"verdict": "fail" if fails else "pass", "gains_dir": str(out.resolve()),
            "gains_sha256": gains, "points": points, "designs": designs,
            "times_s": dict(res.times), "gate_failures": fails}


# --------------------------------------------------------------------------------------------
# certificate
# --------------------------------------------------------------------------------------------

def stage_certificate(ctx: StageContext) -> dict[str, Any]:
    """Mixed-mu robust-stability certificate of the GS-SHIF schedule at every design point."""
    from vtolftc.synthesis.certificate import certify_point, design_points, gains_at

    af = _load(ctx)
    doc = json.loads((Path(ctx.records["synth"]["gains_dir"]) / "gs-shif.json").read_text(
        encoding="utf-8"))
    p = ctx.profile
    rows = []
    pts = design_points(doc)
    chosen = (range(len(pts)) if p["certificate_points"] == "all"
              else sorted({0, len(pts) // 2, len(pts) - 1}))
    for axis in p["certificate_axes"]:
        for i in chosen:
            pt = pts[i]
            c = certify_point(af, axis, pt, gains_at(doc, axis, i), "lagged",
                              grid_n=int(p["certificate_grid_n"]),
                              margin=bool(p["certificate_margin"]))
            rows.append({"axis": axis, "point": pt.number, "airspeed_m_s": pt.airspeed_m_s,
                         "v_min_m_s": pt.v_min_m_s, "v_max_m_s": pt.v_max_m_s,
                         "mu_upper": _fin(c.mu_upper), "mu_lower": _fin(c.mu_lower),
                         "grid_stable": c.grid.stable, "certified": c.certified,
                         "verdict": c.verdict})
            ctx.log(f"  {axis} point {pt.number}: mu <= {c.mu_upper:.3f} ({c.verdict})")
    claimed = rows if p["certificate_claim"] == "all" else [
        r for r in rows if r["point"] in set(p["certificate_claim"])]
    fails = [f"certificate: {r['axis']} point {r['point']} ({r['v_min_m_s']:g}-"
             f"{r['v_max_m_s']:g} m/s): {r['verdict']} (mu upper bound "
             f"{_txt(r['mu_upper'])})" for r in claimed if not r["certified"]]
    return {"verdict": "fail" if fails else "pass", "rows": rows,
            "claimed": len(claimed), "certified": sum(r["certified"] for r in claimed),
            "gate_failures": fails}


def _fin(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _txt(x: float | None) -> str:
    return "inf" if x is None else f"{x:.3f}"


# --------------------------------------------------------------------------------------------
# campaign
# --------------------------------------------------------------------------------------------

def campaign_spec_text(ctx: StageContext) -> str:
    """The campaign spec (TOML) of the profile for this airframe and the synthesised gains."""
    p = ctx.profile
    syn = ctx.records["synth"]
    gains = json.dumps(syn["gains_sha256"], sort_keys=True)
    lines = [
        f"# written by vtolftc certify: airframe sha256 {ctx.airframe_sha256}",
        f"# gains sha256 {hashlib.sha256(gains.encode()).hexdigest()}, code {code_digest()}",
        "[campaign]", 'name = "certify"',
        'description = "vtolftc certify: the fault envelope of the synthesised GS-SHIF"',
        f"duration_s = {float(p['campaign_duration_s'])!r}",
        'controllers = ["gs-shif"]',
        f"phases = {json.dumps(list(p['campaign_phases']))}",
        f"airframe = {json.dumps(str(Path(ctx.airframe_path).resolve()))}",
        f"gains = {json.dumps(syn['gains_dir'])}", ""]
    for fam, gen, group, kinds, k in p["campaign_families"]:
        lines += ["[[faults]]", f'family = "{fam}"', f'generate = "{gen}"',
                  f'actuators = ["{group}"]', f"kinds = {json.dumps(list(kinds))}"]
        if k is not None:
            lines.append(f"k = {int(k)}")
        lines.append("")
    for w in p["campaign_winds"]:
        lines.append(_WINDS[w])
    return "\n".join(lines)


def stage_campaign(ctx: StageContext) -> dict[str, Any]:
    """The envelope campaign of the synthesised GS-SHIF (``vtolftc campaign``'s engine)."""
    import shutil

    from vtolftc.runners.campaign.results import read_results

    out = ctx.out_dir / "campaign"
    text = campaign_spec_text(ctx)
    spec_path = ctx.out_dir / "campaign-spec.toml"
    old = spec_path.read_text(encoding="utf-8") if spec_path.is_file() else None
    if out.exists() and (old != text or not ctx.resume):
        shutil.rmtree(out)  # results of other gains, code or airframe: never mixed in
    spec_path.write_text(text, encoding="utf-8")
    fly_campaign(spec_path, out, jobs=ctx.jobs, scheduler=ctx.scheduler, log=ctx.log)
    rows = read_results(out).to_pylist()
    keep = ("scenario_id", "family", "faults", "phase", "wind", "survived", "outcome",
            "crashed", "recoverable", "recovery_margin", "fly_command")
    rows = [{k: r.get(k) for k in keep} for r in rows]
    return judge_campaign(rows)


def fly_campaign(spec_path: Path, out: Path, *, jobs: int | None, scheduler: str | None,
                 log: Any = print) -> None:
    """Fly the scenarios of ``spec_path`` not yet in ``out`` (``vtolftc campaign --resume``'s
    engine: oracle columns, local pool or Dask, Parquet parts), then write the campaign's own
    ``results.parquet`` and ``report.html``."""
    from vtolftc.runners.campaign.execute import cached_airframe, run_dask, run_local
    from vtolftc.runners.campaign.oracle import oracle_columns
    from vtolftc.runners.campaign.report import write_report
    from vtolftc.runners.campaign.results import PartWriter, read_results, write_final
    from vtolftc.runners.campaign.scenarios import expand, flight_order
    from vtolftc.runners.campaign.spec import SpecError, load_spec

    try:
        spec = load_spec(spec_path)
    except SpecError as exc:
        raise StageError(str(exc)) from None
    scenarios = expand(spec)
    done = read_results(out) if (out / "parts").exists() else None
    done_ids = set() if done is None else set(done.column("scenario_id").to_pylist())
    todo = flight_order([s for s in scenarios if s.scenario_id not in done_ids], 1)
    where = f"Dask scheduler {scheduler}" if scheduler else "local processes"
    log(f"  campaign: {len(scenarios)} scenarios, {len(todo)} to fly on {where}")
    if todo:
        try:
            oracle = oracle_columns(todo)
        except Exception as exc:  # the rows then say "not judged" and the gate fails
            log(f"  recoverability oracle: not judged ({type(exc).__name__}: {exc})")
            oracle = {}
        out.mkdir(parents=True, exist_ok=True)
        writer = PartWriter(out)
        stream = (run_dask(todo, scheduler, tag=spec.sha256[:8]) if scheduler
                  else run_local(todo, jobs))
        try:
            for row in stream:
                row.update(oracle.get(row["scenario_id"], {}))
                writer.add(row)
        except ConnectionError as exc:  # an unreachable --scheduler: bad input
            raise UsageError(str(exc)) from None
        finally:
            writer.close()
            close = getattr(stream, "close", None)
            if close is not None:
                close()
    table = write_final(out)
    write_report(out, table, title=f"Campaign {spec.name}", description=spec.description,
                 airframe=cached_airframe(spec.airframe_path))


def judge_campaign(rows: list[Mapping[str, Any]]) -> dict[str, Any]:
    """The campaign record and its gates from result rows (dicts with ``family``, ``phase``,
    ``survived``, ``recoverable`` (None: not judged) and ``fly_command``)."""
    fails = []
    unjudged = [r for r in rows if r.get("recoverable") is None]
    if unjudged:
        fails.append(f"campaign: {len(unjudged)} scenario(s) not judged by the "
                     "recoverability oracle")
    singles = [r for r in rows if r["family"] == "rotor-off" and r["phase"] in GATE_PHASES
               and r.get("recoverable")]
    doubles = [r for r in rows if r["family"] == "two-rotors-off" and r["phase"] in GATE_PHASES
               and r.get("recoverable")]
    gates = []
    notes = []
    for name, family, sel, need in (
            ("single lift rotor off, hover and mid-transition", "rotor-off", singles,
             SINGLE_MIN),
            ("double lift rotor off, hover and mid-transition", "two-rotors-off", doubles,
             DOUBLE_MIN)):
        k = sum(bool(r["survived"]) for r in sel)
        n = len(sel)
        ok = n == 0 or k / n >= need
        flown = [r for r in rows if r["family"] == family and r["phase"] in GATE_PHASES]
        gates.append({"name": name, "survived": k, "recoverable": n, "min": need,
                      "pass": ok, "flown": len(flown)})
        if n == 0 and flown:
            notes.append(f"campaign: the gate on {name} holds vacuously: the oracle calls none "
                         f"of its {len(flown)} scenarios recoverable (GS-SHIF survived "
                         f"{sum(bool(r['survived']) for r in flown)} of them)")
        if not ok:
            fails.append(f"campaign: GS-SHIF survives {k}/{n} = {k / n:.1%} of the recoverable "
                         f"{name}, below {need:.0%}")
    cells: dict[str, dict[str, int]] = {}
    for r in rows:
        c = cells.setdefault(f"{r['family']}|{r['phase']}",
                             {"scenarios": 0, "survived": 0, "recoverable": 0,
                              "survived_recoverable": 0})
        c["scenarios"] += 1
        c["survived"] += bool(r["survived"])
        c["recoverable"] += bool(r.get("recoverable"))
        c["survived_recoverable"] += bool(r.get("recoverable")) and bool(r["survived"])
    failures = [dict(r) for r in rows if not r["survived"]]
    return {"verdict": "fail" if fails else "pass", "scenarios": len(rows),
            "survived": sum(bool(r["survived"]) for r in rows), "gates": gates,
            "cells": cells, "failures": failures, "gate_failures": fails, "notes": notes}


# --------------------------------------------------------------------------------------------
# SITL mission
# --------------------------------------------------------------------------------------------

def stage_sitl(ctx: StageContext) -> dict[str, Any]:
    """The reference VTOL mission (takeoff, transition, four waypoints, back transition, land)
    flown by the SITL processes over UDP with the synthesised gains."""
    from vtolftc.runners.mission_sitl import fly_sitl_mission
    from vtolftc.runners.sitl import SitlError

    out = ctx.stage_dir("sitl")
    gains = Path(ctx.records["synth"]["gains_dir"])
    try:
        rec = fly_sitl_mission(out, transport="udp", airframe=Path(ctx.airframe_path),
                               gains_dir=gains)
    except SitlError as exc:
        raise StageError(f"SITL mission: {exc}") from None
    return judge_mission(rec, n_items=len(rec["items"]))


def judge_mission(rec: Mapping[str, Any], n_items: int) -> dict[str, Any]:
    """The SITL record and its gate from :func:`vtolftc.runners.mission_sitl.fly_sitl_mission`'s
    record (``pos`` NED samples, ``reached`` item numbers)."""
    pos = list(rec.get("pos", []))
    fails = []
    if not pos:
        fails.append("sitl: no position received")
        home_m, alt_m = math.inf, math.inf
    else:
        home_m = math.hypot(pos[-1][0], pos[-1][1])
        alt_m = -pos[-1][2]
    reached = list(rec.get("reached", []))
    if reached != list(range(n_items)):
        fails.append(f"sitl: mission items reached {reached}, expected 0..{n_items - 1}")
    if pos and not (home_m < LAND_RADIUS_M and alt_m < 0.5):
        fails.append(f"sitl: ended {home_m:.1f} m from home at {alt_m:.1f} m height "
                     f"(gate: landed within {LAND_RADIUS_M:g} m)")
    step = max(1, len(pos) // 1500)
    return {"verdict": "fail" if fails else "pass",
            "landed_from_home_m": home_m if math.isfinite(home_m) else None,
            "final_height_m": alt_m if math.isfinite(alt_m) else None,
            "reached": reached, "items": n_items,
            "track_ne_m": [[float(p[0]), float(p[1])] for p in pos[::step]],
            "fw": [bool(f) for f in list(rec.get("fw", []))[::step]],
            "flight_wall_s": rec.get("flight_wall_s"), "gate_failures": fails}


def sitl_command(airframe: Path, gains_dir: str, out: Path) -> str:
    """A command that re-flies the SITL mission of a certify run."""
    code = ("from pathlib import Path; from vtolftc.runners.mission_sitl import fly_sitl_mission; "
            f"r = fly_sitl_mission(Path({str(out)!r}), airframe=Path({str(airframe)!r}), "
            f"gains_dir=Path({gains_dir!r})); print(r['reached'], r['pos'][-1])")
    return shlex.join(["python", "-c", code])


def default_stages() -> list[Stage]:
    """trim -> synth -> certificate -> campaign -> sitl."""
    return [
        Stage("trim", "trim table", stage_trim),
        Stage("synth", "robust synthesis (vtolftc synth --method robust)", stage_synth),
        Stage("certificate", "mixed-mu certificate of GS-SHIF", stage_certificate,
              needs=("synth",)),
        Stage("campaign", "fault-envelope campaign judged by the recoverability oracle",
              stage_campaign, needs=("synth",)),
        Stage("sitl", "SITL VTOL mission over UDP", stage_sitl, needs=("synth",)),
    ]
