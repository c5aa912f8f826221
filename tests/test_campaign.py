"""Fault campaigns: spec validation, expansion, outcome, Parquet parts, pool = Dask, resume."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from support.procs import descendants

from vtolftc.cli.main import run
from vtolftc.runners.campaign.outcome import outcome
from vtolftc.runners.campaign.results import SCHEMA, TIMING_COLUMNS, PartWriter, read_results
from vtolftc.runners.campaign.scenarios import expand
from vtolftc.runners.campaign.spec import SpecError, load_spec, parse_spec

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGNS = ROOT / "campaigns"
VTOLFTC = Path(sys.executable).with_name("vtolftc")  # the installed entry point
ROTORS = [f"rotor_{n}" for n in ("1a", "1b", "2a", "2b", "3a", "3b", "4a", "4b")]

# A dozen short scenarios using every axis: 2 controllers x 3 fault sets x 2 winds (one with
# a gust), a perturbed airframe and seeded state noise.
SMALL = """
[campaign]
name = "small"
duration_s = 24.0
controllers = ["gs-shif", "lqr"]
phases = ["transition+1"]

[[faults]]
family = "rotor"
generate = "each"
actuators = ["rotor_2a"]
kinds = ["off", "loss"]
magnitudes = [0.5]

[[faults]]
family = "elevator"
generate = "list"
sets = [["elevator:stuck"]]

[[wind]]
name = "calm"

[[wind]]
name = "gust"
steady_ned_m_s = [1.0, 2.0, 0.0]
gusts = [{ after_fault_s = 0.5, duration_s = 1.5, amplitude_ned_m_s = [0.0, 3.0, -0.5] }]

[[perturbation]]
name = "heavy"
mass_scale = 1.05
inertia_scale = [1.1, 0.95, 1.0]
cg_offset_m = [0.01, 0.0, 0.005]

[noise]
level = "typical"
seeds = [7]
"""

MINIMAL = """
[campaign]
name = "m"
duration_s = 50.0
[[faults]]
family = "f"
actuators = ["rotor_1a"]
kinds = ["off"]
"""


def _spec_file(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# ----------------------------------------------------------------------------------------------
# Spec validation and expansion
# ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize(("edit", "needle"), [
    (('actuators = ["rotor_1a"]', 'actuators = ["rotor_9z"]'), "unknown actuator 'rotor_9z'"),
    (('kinds = ["off"]', 'kinds = ["loss"]\nmagnitudes = [1.5]'),
     "field 'faults[0].magnitudes' = 1.5: expected a loss in (0, 1]"),
    (('kinds = ["off"]', 'kinds = ["off"]\nkindz = 1'), "unknown key 'faults[0].kindz'"),
    (('duration_s = 50.0', 'duration_s = 50.0\ncolour = "red"'), "unknown key 'campaign.colour'"),
    (('name = "m"', 'name = "m"\ncontrollers = ["pid"]'), "field 'campaign.controllers'"),
    (('kinds = ["off"]', 'kinds = ["off"]\n[[exclude]]\nfamily = "f"'),
     "the product of the axes is empty"),
    (('duration_s = 50.0', 'duration_s = 50.0\nphases = [55.0]'), "field 'campaign.phases' = 55.0"),
    (('duration_s = 50.0', 'duration_s = -1'), "field 'campaign.duration_s' = -1"),
])
def test_bad_spec_is_one_line_and_exit_2(tmp_path, capsys, edit, needle):
    old, new = edit
    assert old in MINIMAL
    spec = _spec_file(tmp_path, MINIMAL.replace(old, new, 1))
    code = run(["campaign", str(spec), "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1, err
    assert needle in err
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()  # nothing flown or written


def test_bad_spec_in_a_subprocess_is_one_line(tmp_path):
    spec = _spec_file(tmp_path, MINIMAL.replace('"rotor_1a"', '"rotor_1x"'))
    p = subprocess.run([str(VTOLFTC), "campaign", str(spec)],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert p.returncode == 2
    assert len(p.stderr.strip().splitlines()) == 1 and "rotor_1x" in p.stderr


def test_shipped_specs_expand_to_the_documented_counts():
    counts = {p.stem: len(expand(load_spec(p))) for p in CAMPAIGNS.glob("*.toml")}
    n_single, n_double = 8, math.comb(8, 2)
    n_partial, n_surf_push = 8 * 3, (5 + 2) * 2
    assert counts["single-rotor"] == 8 * 3 * 3
    assert counts["paper"] == 2 * 3
    assert counts["envelope"] == (n_single + n_double + n_partial + n_surf_push) * 3 * 3 * 2
    assert counts["envelope"] >= 1000
    assert counts["envelope-paper-gains"] == counts["envelope"] // 3  # GS-SHIF only


def test_expansion_is_deterministic_and_generators_are_complete():
    text = MINIMAL.replace('actuators = ["rotor_1a"]\nkinds = ["off"]',
                           'generate = "subsets"\nk = 3\nactuators = ["lift_rotors"]\n'
                           'kinds = ["off", "loss"]\nmagnitudes = [0.25, 0.75]')
    a = expand(parse_spec(text))
    b = expand(parse_spec(text))
    assert [s.scenario_id for s in a] == [s.scenario_id for s in b]
    n_sets = math.comb(8, 3) * 3
    assert len(a) == n_sets * 3 * 3  # x 3 default controllers x 3 default phases
    sets = {s.fault_set.faults for s in a}
    assert len(sets) == n_sets
    assert len({s.scenario_id for s in a}) == len(a)
    # every 3-subset of the lift rotors, each with off, 25 % and 75 % loss
    subsets = {tuple(x[0] for x in fs) for fs in sets}
    assert subsets == {tuple(c) for c in __import__("itertools").combinations(ROTORS, 3)}
    assert [s.index for s in a] == list(range(len(a)))


def test_exclude_filters_and_phase_times():
    text = MINIMAL.replace('name = "m"', 'name = "m"\ncontrollers = ["gs-shif", "lqr"]\n'
                           'phases = ["hover", "transition+4", "cruise", 12.5]')
    text += '[[exclude]]\ncontroller = "lqr"\nphase = ["hover", "t=12.5"]\n'
    sc = expand(parse_spec(text))
    got = {(s.controller, s.phase, s.fault_time_s) for s in sc}
    assert got == {("gs-shif", "hover", 15.0), ("gs-shif", "transition+4", 24.0),
                   ("gs-shif", "cruise", 40.0), ("gs-shif", "t=12.5", 12.5),
                   ("lqr", "transition+4", 24.0), ("lqr", "cruise", 40.0)}


def test_spec_error_names_field_value_and_expectation():
    with pytest.raises(SpecError, match=r"field 'wind\[0\]\.steady_ned_m_s' = \[0, 99, 0\]: "
                                        r"expected three numbers in \[-30, 30\]"):
        parse_spec(MINIMAL + '[[wind]]\nname = "w"\nsteady_ned_m_s = [0, 99, 0]\n')


# ----------------------------------------------------------------------------------------------
# Outcome and results files
# ----------------------------------------------------------------------------------------------

def test_outcome_definition():
    ok = {"crashed": False, "final_altitude_error_m": -4.9, "final_roll_deg": 19.9,
          "final_pitch_deg": -19.9}
    assert outcome(ok) == "survived"
    assert outcome({**ok, "crashed": True}) == "crashed"
    assert outcome({**ok, "final_altitude_error_m": 5.01}) == "altitude"
    assert outcome({**ok, "final_altitude_error_m": math.nan}) == "altitude"
    assert outcome({**ok, "final_roll_deg": -20.5}) == "attitude"
    assert outcome({**ok, "final_pitch_deg": 21.0}) == "attitude"


def _row(i: int, sid: str, survived: bool = True) -> dict:
    return {"index": i, "scenario_id": sid, "controller": "lqr", "family": "f",
            "faults": "rotor_1a:off", "phase": "hover", "survived": survived,
            "crash_time_s": None, "outcome": "survived" if survived else "crashed"}


def test_parts_merge_dedupe_and_sort(tmp_path):
    w = PartWriter(tmp_path, batch=2, interval_s=1e9)
    for i in (3, 1, 2):
        w.add(_row(i, f"s{i}"))
    assert len(list((tmp_path / "parts").glob("part-*.parquet"))) == 1  # batch of 2 written
    w.add(_row(1, "s1", survived=False))  # a duplicate: the first written wins
    w.close()
    (tmp_path / "parts" / ".part-000009.parquet.123.tmp").write_bytes(b"half a file")
    t = read_results(tmp_path)
    assert t.schema == SCHEMA
    assert t.column("index").to_pylist() == [1, 2, 3]
    assert t.column("survived").to_pylist() == [True, True, True]
    assert math.isnan(t.column("crash_time_s")[0].as_py())
    w2 = PartWriter(tmp_path)  # a resumed writer never overwrites a part
    w2.add(_row(4, "s4"))
    w2.close()
    assert len(list((tmp_path / "parts").glob("part-*.parquet"))) == 3
    assert read_results(tmp_path).num_rows == 4


# ----------------------------------------------------------------------------------------------
# End to end: pool = Dask, kill and resume
# ----------------------------------------------------------------------------------------------

def _assert_same_results(a: pa.Table, b: pa.Table) -> None:
    """Every column bit for bit, except the wall times."""
    assert a.num_rows == b.num_rows
    assert a.schema == b.schema
    for name in a.column_names:
        if name in TIMING_COLUMNS:
            continue
        x, y = a.column(name).to_numpy(zero_copy_only=False), b.column(name).to_numpy(
            zero_copy_only=False)
        if x.dtype.kind == "f":
            assert np.array_equal(x.view(np.int64), y.view(np.int64)), name
        else:
            assert list(x) == list(y), name


@pytest.fixture(scope="module")
def small_reference(tmp_path_factory):
    """The small spec flown uninterrupted on a local pool of 2 processes."""
    d = tmp_path_factory.mktemp("campaign")
    spec = _spec_file(d, SMALL)
    assert len(expand(load_spec(spec))) == 12
    code = run(["campaign", str(spec), "--out", str(d / "pool"), "--jobs", "2",
                "--no-progress"])
    assert code == 0
    return spec, read_results(d / "pool")


@pytest.mark.slow
def test_local_pool_and_dask_cluster_give_identical_results(small_reference, tmp_path):
    from distributed import LocalCluster

    spec, pool = small_reference
    assert pool.num_rows == 12
    # the scenarios really differ (faults, wind, controllers act), not a constant
    assert len(set(pool.column("max_attitude_excursion_deg").to_pylist())) >= 6
    assert len(set(pool.column("final_altitude_error_m").to_pylist())) >= 6
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        code = run(["campaign", str(spec), "--out", str(tmp_path / "dask"), "--scheduler",
                    cluster.scheduler_address, "--no-progress"])
    assert code == 0
    _assert_same_results(pool, read_results(tmp_path / "dask"))
    assert (tmp_path / "dask" / "report.html").is_file()


def _raw_rows(out: Path) -> int:
    import pyarrow.parquet as pq

    return sum(pq.read_metadata(p).num_rows for p in (out / "parts").glob("part-*.parquet"))


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_campaign_resumes_only_the_missing_scenarios(small_reference, tmp_path, sig,
                                                            capsys):
    spec, reference = small_reference
    out = tmp_path / "out"
    cmd = [str(VTOLFTC), "campaign", str(spec), "--out", str(out),
           "--jobs", "2", "--batch", "1", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while _raw_rows(out) < 4 if (out / "parts").is_dir() else True:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no results within 300 s"
            time.sleep(0.1)
        workers = descendants(proc.pid)
        assert workers  # the pool's processes
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
    if sig == signal.SIGTERM:
        assert proc.returncode == 130
        assert "run again with --resume" in err
        assert "Traceback" not in err
    else:
        assert proc.returncode == -signal.SIGKILL
    n_done = read_results(out).num_rows
    assert 4 <= n_done < 12
    # without --resume the folder is refused
    assert run(["campaign", str(spec), "--out", str(out), "--no-progress"]) == 2
    capsys.readouterr()
    assert run(["campaign", str(spec), "--out", str(out), "--resume", "--jobs", "2",
                "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert f"({n_done} already done, {12 - n_done} to fly)" in printed
    assert _raw_rows(out) == 12  # nothing flown twice
    _assert_same_results(reference, read_results(out / "results.parquet"))
    # and the worker processes of the killed campaign are gone
    deadline = time.monotonic() + 60
    while _alive(workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _alive(workers)


def _alive(pids: set[int]) -> set[int]:
    live = set()
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            continue
        if state != "Z":
            live.add(pid)
    return live


@pytest.mark.slow
def test_compare_and_gates(small_reference, tmp_path, capsys):
    _, ref = small_reference
    # a copy with one outcome flipped
    rows = ref.to_pylist()
    rows[0]["survived"] = not rows[0]["survived"]
    rows[0]["outcome"] = "survived" if rows[0]["survived"] else "crashed"
    w = PartWriter(tmp_path / "b")
    for r in rows:
        w.add(r)
    w.close()
    a_dir = tmp_path / "a"
    w = PartWriter(a_dir)
    for r in ref.to_pylist():
        w.add(r)
    w.close()
    assert run(["campaign", "--compare", str(a_dir), str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    assert "outcome changed in 1 scenarios" in out
    assert rows[0]["scenario_id"] in out
    from vtolftc.runners.campaign.report import check_gates
    from vtolftc.runners.campaign.spec import Gate

    surv = sum(ref.column("survived").to_pylist()) / ref.num_rows
    assert check_gates([Gate(0.0)], ref) == []
    assert check_gates([Gate(1.0)], ref) != [] if surv < 1.0 else True
    fails = check_gates([Gate(1.0, family="rotor", controller="lqr")], ref)
    lqr_rotor = [r for r in ref.to_pylist() if r["family"] == "rotor"
                 and r["controller"] == "lqr"]
    assert bool(fails) == (not all(r["survived"] for r in lqr_rotor))


@pytest.mark.slow
def test_fly_command_reflies_the_scenario(small_reference, tmp_path):
    """The worst-scenario command re-flies the campaign's very flight (same metrics)."""
    import shlex

    _, ref = small_reference
    row = next(r for r in ref.to_pylist() if r["wind"] == "gust")
    argv = shlex.split(row["fly_command"])[1:]
    i = argv.index("--out")
    argv[i + 1] = str(tmp_path / "fly")
    assert run([*argv, "--no-plots"]) == 0
    m = json.loads((tmp_path / "fly" / "metrics.json").read_text())
    assert m["max_attitude_excursion_deg"] == row["max_attitude_excursion_deg"]
    assert m["rmse_roll_deg"] == row["rmse_roll_deg"]
    assert m["crashed"] == row["crashed"]


@pytest.mark.slow
def test_report_only_and_partial_folders(small_reference, tmp_path, capsys):
    spec, ref = small_reference
    out = tmp_path / "partial"
    w = PartWriter(out)
    for r in ref.to_pylist()[:5]:
        w.add(r)
    w.close()
    (out / "campaign.json").write_text(
        json.dumps({"spec_sha256": load_spec(spec).sha256}), encoding="utf-8")
    assert run(["campaign", str(spec), "--out", str(out), "--report-only"]) == 0
    printed = capsys.readouterr().out
    assert "(partial: 5 of 12 scenarios flown)" in printed
    assert (out / "report.html").is_file() and (out / "survival_heatmap.png").is_file()
    assert read_results(out / "results.parquet").num_rows == 5
    # another spec's folder is refused
    other = _spec_file(tmp_path, SMALL.replace('name = "small"', 'name = "other"'), "o.toml")
    assert run(["campaign", str(other), "--out", str(out), "--resume"]) == 2


# ----------------------------------------------------------------------------------------------
# The physical recoverability oracle's columns
# ----------------------------------------------------------------------------------------------

ORACLE = """
[campaign]
name = "oracle"
duration_s = 50.0
controllers = ["gs-shif", "lqr"]
phases = ["hover", "cruise", "transition"]

[[faults]]
family = "rotor-off"
actuators = ["lift_rotors"]
kinds = ["off"]

[[faults]]
family = "all-lift"
generate = "list"
sets = [["lift_rotors:off"]]

[[wind]]
name = "calm"

[[wind]]
name = "gust"
steady_ned_m_s = [0.0, 4.0, 0.0]
gusts = [{ after_fault_s = 1.0, duration_s = 3.0, amplitude_ned_m_s = [0.0, 3.0, -1.0] }]
"""


def _trim_conditions() -> dict:
    """Phase conditions from the nominal trims (no reference flight): hover at 15 s,
    wing-borne 18 m/s at 40 s; the transition (23 s) left out (the flight did not get there)."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.vehicle.recoverability import trim_condition
    from vtolftc.runners.campaign.oracle import PhaseCondition

    af = load_airframe()
    out = {}
    for t, mode, trim, v in ((15.0, "HOVER", "hover", 0.0), (40.0, "FIXED_WING", "wing", 18.0)):
        c = trim_condition(af, trim, v)
        out[t] = PhaseCondition(t, mode, c.speed_m_s, c.pitch_rad, 0.0, c.actuator_positions)
    return out


def test_oracle_columns_per_flight_condition():
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.vehicle.recoverability import (
        RECOVERABLE_MIN_MARGIN,
        FlightCondition,
        assess,
    )
    from vtolftc.runners.campaign.oracle import oracle_columns
    from vtolftc.runners.campaign.report import recoverable_lines

    scenarios = expand(parse_spec(ORACLE))
    cols = oracle_columns(scenarios, _trim_conditions())
    assert set(cols) == {s.scenario_id for s in scenarios}
    by_cond: dict = {}
    for s in scenarios:
        c = cols[s.scenario_id]
        if s.phase == "transition":  # not reached by the reference: not judged
            assert math.isnan(c["recovery_margin"]) and c["recoverable"] is False
            continue
        assert c["recoverable"] == (c["recovery_margin"] >= RECOVERABLE_MIN_MARGIN)
        # one verdict per flight condition, whatever the controller
        by_cond.setdefault((s.faults_label, s.phase, s.wind.name), set()).add(
            (c["recoverable"], c["recovery_margin"]))
    assert all(len(v) == 1 for v in by_cond.values())
    verdict = {k: next(iter(v)) for k, v in by_cond.items()}
    g = load_airframe().gravity_m_s2
    for r in ROTORS:
        assert verdict[(f"{r}:off", "hover", "calm")][0]            # every single rotor
        assert verdict[(f"{r}:off", "cruise", "gust")][0]           # the wing does not care
    # the wind relative to the vehicle: in hover (position held) the steady wind and the
    # steady wind plus the gust's peak; in cruise (drifting with the air) the gust's peak only
    conds = _trim_conditions()
    P = ["pusher_left", "pusher_right"]
    hov = FlightCondition("hover", conds[15.0].speed_m_s, conds[15.0].pitch_rad,
                          (0.0, 4.0, 0.0), conds[15.0].actuator_positions)
    cru = FlightCondition("fixed_wing", conds[40.0].speed_m_s, conds[40.0].pitch_rad,
                          (0.0, 0.0, 0.0), conds[40.0].actuator_positions)
    af = load_airframe()
    for r in ("rotor_1a", "rotor_3b"):
        want_h = assess(af, [(r, "off", 1.0)], hov, gust_peaks_ned_m_s=[(0.0, 3.0, -1.0)],
                        hold=P).margin
        want_c = assess(af, [(r, "off", 1.0)], cru, gust_peaks_ned_m_s=[(0.0, 3.0, -1.0)],
                        ).margin
        assert verdict[(f"{r}:off", "hover", "gust")][1] == want_h
        assert verdict[(f"{r}:off", "cruise", "gust")][1] == want_c
    rec, margin = verdict[("lift_rotors:off", "hover", "calm")]
    assert not rec and margin == pytest.approx(-g, rel=1e-6)        # nothing holds the weight
    assert verdict[("lift_rotors:off", "cruise", "calm")][0]        # the wing alone flies
    # the report's table: survived / recoverable per family and phase
    rows = []
    for s in scenarios:
        rows.append({**_row(s.index, s.scenario_id, survived=s.controller == "gs-shif"),
                     "controller": s.controller, "family": s.family, "phase": s.phase,
                     "faults": s.faults_label, "wind": s.wind.name, "perturbation": "nominal",
                     "seed": 0, **cols[s.scenario_id]})
    from vtolftc.runners.campaign.results import _table

    lines = recoverable_lines(_table(rows))
    assert lines[0] == "| family | phase | recoverable | gs-shif | lqr |"
    assert "| rotor-off | hover | 16/16 | 16/16 (100 %) | 0/16 (0 %) |" in lines
    assert "| all-lift | hover | 0/2 | —, +2 unrecoverable survived | — |" in lines
    assert not any("transition" in ln for ln in lines)  # not judged: not counted


@pytest.mark.slow
def test_campaign_results_carry_the_oracle(small_reference):
    spec, ref = small_reference
    rows = ref.to_pylist()
    verdicts: dict = {}
    for r in rows:
        assert r["recoverable"] is not None and math.isfinite(r["recovery_margin"])
        verdicts.setdefault((r["faults"], r["phase"], r["wind"], r["perturbation"], r["seed"]),
                            set()).add((r["recoverable"], r["recovery_margin"]))
    assert all(len(v) == 1 for v in verdicts.values())  # the controllers share a verdict
    # rotor 2a off or at half effectiveness, elevator stuck, 1 s into the transition: all
    # recoverable for DS-1, with less margin for the rotor off than for the half loss
    assert all(r["recoverable"] for r in rows)
    m = {k[0] + "/" + k[2]: next(iter(v))[1] for k, v in verdicts.items()}
    assert m["rotor_2a:off/calm"] < m["rotor_2a:loss=0.5/calm"]
    html_text = (Path(spec).parent / "pool" / "report.html").read_text(encoding="utf-8")
    assert "Survived / recoverable per family and phase" in html_text


def test_a_failing_oracle_leaves_the_rows_not_judged(monkeypatch, capsys):
    import vtolftc.runners.campaign.oracle as oracle
    from vtolftc.cli.cmd_campaign import _oracle

    def broken(todo):
        raise RuntimeError("reference flight crashed")

    monkeypatch.setattr(oracle, "oracle_columns", broken)
    assert _oracle(expand(parse_spec(MINIMAL))) == {}
    assert "recoverability oracle: not judged (RuntimeError: reference flight crashed)" \
        in capsys.readouterr().out


def test_oracle_rules_per_mode():
    """In a transition the forward force is free (the transition accelerates); in hover the
    pushers are held where the reference flight had them."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.firmware_sim.vehicle.recoverability import (
        FlightCondition,
        assess,
        trim_condition,
    )
    from vtolftc.runners.campaign.oracle import PhaseCondition, judge

    af = load_airframe()
    pos = list(trim_condition(af, "rotor-assisted", 4.0).actuator_positions)
    i, j = af.actuator_index("pusher_left"), af.actuator_index("pusher_right")
    pos[i] = pos[j] = 0.68          # the transition's pushers: far more than holds 4 m/s
    stuck = [("pusher_left", "stuck", 0.0)]
    trans = PhaseCondition(23.0, "FRONT_TRANSITION", 4.0, 0.0, 0.0, tuple(pos))
    assert judge(af, stuck, trans).recoverable
    # holding the airspeed as well (Fx balanced) the stuck pusher's yaw cannot be trimmed
    assert not assess(af, stuck, FlightCondition("t", 4.0, 0.0, (0.0, 0.0, 0.0),
                                                 tuple(pos))).recoverable
    # the same positions in hover: pushers held at 68 %, their thrust cannot be leaned against
    hover = PhaseCondition(15.0, "HOVER", 0.0, 0.0, 0.0, tuple(pos))
    assert not judge(af, [], hover).recoverable
    assert judge(af, [], PhaseCondition(15.0, "HOVER", 0.0, 0.0, 0.0,
                                        tuple(0.0 if k in (i, j) else v
                                              for k, v in enumerate(pos)))).recoverable
