"""The shipped results of docs/ds1-claims still match the gains and code that made them.

Every results file there is stamped in ``PROVENANCE.json`` by ``benchmarks/regen_docs.py``
(:mod:`vtolftc.base.provenance`): the sha256 of the gain files and airframe file it was made
from, the digest of its records, and the digest of its flights' actuator commands. The fast
tests check the stamps against the shipped files (a re-synthesised gain file or a hand-edited
number fails them) and table 3 against the gain files; the slow test re-flies table 4's case 1
with the three controllers and compares every stored number to the last digit. Each check is
shown to fail on a mutated copy.
"""

from __future__ import annotations

import importlib.util
import json
import math
import shutil
import sys
from pathlib import Path
from types import ModuleType

import pytest

from vtolftc.base.provenance import (
    SIDECAR,
    canonical_sha256,
    check_folder,
    compare_records,
    flights_sha256,
    make_stamp,
)

ROOT = Path(__file__).resolve().parents[1]
CLAIMS = ROOT / "docs" / "ds1-claims"


def _regen() -> ModuleType:
    spec = importlib.util.spec_from_file_location("regen_docs_under_test",
                                                  ROOT / "benchmarks" / "regen_docs.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod           # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def _copy_tree(tmp_path: Path) -> tuple[Path, Path]:
    """A copy of docs/ds1-claims' JSON files and every stamped input, in a fake root."""
    root = tmp_path / "repo"
    folder = root / "docs" / "ds1-claims"
    folder.mkdir(parents=True)
    prov = json.loads((CLAIMS / SIDECAR).read_text())
    for name, st in prov["files"].items():
        shutil.copy(CLAIMS / name, folder / name)
        for rel in st["inputs"]:
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(ROOT / rel, root / rel)
    shutil.copy(CLAIMS / SIDECAR, folder / SIDECAR)
    return root, folder


def test_every_shipped_results_file_matches_its_stamp():
    problems = check_folder(CLAIMS, ROOT)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("folder", ["docs/ds1-synthesis", "docs/ds1-synthesis-robust",
                                    "docs/campaigns/single-rotor"])
def test_every_report_file_matches_its_stamp(folder):
    problems = check_folder(ROOT / folder, ROOT, pattern="*")
    assert not problems, "\n".join(problems)


def _md_rows(text: str, head: str) -> list[list[str]]:
    """Cells of the markdown table whose header row starts with ``head``."""
    lines = text.splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith(head))
    rows = []
    for ln in lines[i + 2:]:
        if not ln.startswith("|"):
            break
        rows.append([c.strip() for c in ln.strip("|").split("|")])
    return rows


@pytest.mark.parametrize(("folder", "gains", "head", "cols"), [
    ("docs/ds1-synthesis", "paper/gs-shif.json", "| axis | No. | mu_Delta | gap |", (2, 4)),
    ("docs/ds1-synthesis-robust", "gs-shif.json", "| axis | No. | gamma |", (-2, -1)),
])
def test_synthesis_report_mu_tables_are_the_gain_files(folder, gains, head, cols):
    """The report beside the gains says what the gain file records (3 decimals)."""
    doc = json.loads((ROOT / "firmware_sim" / "autopilot" / "gains" / gains).read_text())
    rows = _md_rows((ROOT / folder / "README.md").read_text(), head)
    n = len(doc["airspeed_breakpoints_m_s"])
    assert len(rows) == 3 * n
    for r in rows:
        mu = doc["axes"][r[0]]["metadata"]["mu"][int(r[1]) - 1]
        assert (r[cols[0]], r[cols[1]]) == (f"{mu['mu_rs']:.3f}", f"{mu['mu_rp']:.3f}"), r


def test_stamps_name_the_gain_files_and_a_command_that_regenerates_them():
    prov = json.loads((CLAIMS / SIDECAR).read_text())
    regen = _regen()
    targets = regen.targets()
    for name, st in prov["files"].items():
        assert st["command"] == f"python benchmarks/regen_docs.py --files {name}"
        assert name in targets
        want = {p.relative_to(ROOT).as_posix() for p in targets[name].inputs}
        assert set(st["inputs"]) == want
        assert any(k.startswith("firmware_sim/autopilot/gains/") for k in st["inputs"])
    # the flight files carry one command digest per record
    for name in ("robust.json", "paper.json", "robust-gs-shif.json"):
        recs = json.loads((CLAIMS / name).read_text())
        assert all(len(r["commands_sha256"]) == 64 for r in recs)
        assert prov["files"][name]["flights_sha256"] == flights_sha256(recs)


def test_a_changed_gain_file_makes_the_results_stale(tmp_path):
    root, folder = _copy_tree(tmp_path)
    assert check_folder(folder, root) == []
    gains = root / "firmware_sim" / "autopilot" / "gains" / "gs-shif.json"
    doc = json.loads(gains.read_text())
    doc["axes"]["roll"]["ki_rate"][2] *= 1.01
    gains.write_text(json.dumps(doc, indent=2))
    problems = check_folder(folder, root)
    stale = {p.split(":")[0] for p in problems}
    # every file made from the robust GS-SHIF gains, and no other
    assert stale == {"table3.json", "robust.json", "robust-gs-shif.json", "robust-delay.json",
                     "robust-delay-long.json", "certificate.json"} & set(
        json.loads((folder / SIDECAR).read_text())["files"])
    assert all("firmware_sim/autopilot/gains/gs-shif.json changed" in p for p in problems)


def test_an_edited_or_unstamped_results_file_is_reported(tmp_path):
    root, folder = _copy_tree(tmp_path)
    recs = json.loads((folder / "robust.json").read_text())
    # one number, one unit in the last place
    recs[0]["rmse_roll_deg"] = math.nextafter(recs[0]["rmse_roll_deg"], math.inf)
    (folder / "robust.json").write_text(json.dumps(recs, indent=1) + "\n")
    (folder / "extra.json").write_text("[]\n")
    problems = check_folder(folder, root)
    assert any(p.startswith("robust.json: records differ") for p in problems), problems
    assert "extra.json: no stamp in PROVENANCE.json" in problems
    # re-indenting is not a change
    recs[0]["rmse_roll_deg"] = json.loads((CLAIMS / "robust.json").read_text())[0][
        "rmse_roll_deg"]
    (folder / "robust.json").write_text(json.dumps(recs))
    assert not any(p.startswith("robust.json") for p in check_folder(folder, root))
    # a changed flight digest alone is reported too
    recs[1]["commands_sha256"] = "0" * 64
    stamp = make_stamp(recs, command="x", inputs=[], root=root)
    assert stamp["flights_sha256"] != flights_sha256(
        json.loads((CLAIMS / "robust.json").read_text()))


def test_canonical_digest_sees_every_digit_and_ignores_layout():
    a = [{"x": 0.1 + 0.2, "y": None, "z": "s"}]
    b = json.loads(json.dumps(a, indent=4))
    assert canonical_sha256(a) == canonical_sha256(b)
    b[0]["x"] = math.nextafter(b[0]["x"], 1.0)
    assert canonical_sha256(a) != canonical_sha256(b)


T3_KEY = ("design", "axis", "point")
MARGIN_REL = 1e-12  # LAPACK quantities: the CPU's rounding (see the delay-margin test)


def test_table3_is_what_the_gain_files_record():
    """mu and the robust delay margins, read from the gain files (no computation)."""
    stored = json.loads((CLAIMS / "table3.json").read_text())
    fresh = _regen().table3_records(paper_margins=False)
    assert len(fresh) == len(stored) == 3 * (6 + 7)
    assert compare_records(stored, fresh, T3_KEY) == []
    # a stale copy (the paper's yaw 1 mu_Delta-hat as it was typed before) is caught
    stale = [dict(r) for r in stored]
    k = next(i for i, r in enumerate(stale) if (r["design"], r["axis"], r["point"]) ==
             ("paper", "yaw", 1))
    stale[k]["mu_rp"] = 5.000
    diff = compare_records(stale, fresh, T3_KEY)
    assert len(diff) == 1 and "mu_rp" in diff[0]


@pytest.mark.slow
def test_table3_paper_delay_margins_recompute_within_the_machines_rounding():
    """The paper design's delay margins, computed on the robust design plant (~10 s).

    Equal to 1e-12 relative, not to the last digit: they go through LAPACK, whose OpenBLAS
    kernels depend on the CPU (on an AVX512_SPR Xeon, 3 of the 39 margins differ from the
    stored ones in their last digit, e.g. 173.55956160258341 against 173.5595616025834 ms);
    a change of the code or the gains moves them by far more."""
    stored = json.loads((CLAIMS / "table3.json").read_text())
    fresh = _regen().table3_records()
    assert all("delay_margin_ms" in r for r in fresh)
    assert compare_records(stored, fresh, T3_KEY, rel=MARGIN_REL) == []
    stale = [dict(r) for r in stored]
    stale[4]["delay_margin_ms"] *= 1.0 + 1e-9
    diff = compare_records(stale, fresh, T3_KEY, rel=MARGIN_REL)
    assert len(diff) == 1 and "delay_margin_ms" in diff[0]


def test_compare_records_tolerance_is_relative_and_exact_by_default():
    a = [{"label": "x", "controller": "c", "v": 100.0, "n": float("nan")}]
    b = [{"label": "x", "controller": "c", "v": math.nextafter(100.0, 0.0), "n": float("nan")}]
    assert len(compare_records(a, b)) == 1
    assert compare_records(a, b, rel=MARGIN_REL) == []
    b[0]["v"] = 100.0 * (1.0 - 1e-11)
    assert len(compare_records(a, b, rel=MARGIN_REL)) == 1


def test_regen_refuses_an_unknown_file_in_one_line(capsys):
    assert _regen().main(["--files", "nope.json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.json" in err[0]


@pytest.mark.slow
def test_table4_case1_flies_the_stored_numbers_to_the_last_digit():
    """Re-fly the robust design's case 1 with GS-SHIF, SHIF and LQR (3 x 40 s, in-process)."""
    regen = _regen()
    stored = json.loads((CLAIMS / "robust.json").read_text())
    fresh = [regen.fly(job) for job in regen.table4_jobs("robust", cases=("1",))]
    assert [r["controller"] for r in fresh] == ["gs-shif", "shif", "lqr"]
    assert compare_records(stored, fresh) == []
    # every field compared, including the flight's command digest
    assert all("commands_sha256" in r and "rmse_yaw_deg" in r for r in fresh)
    # a stored copy one ulp off, or from another flight, is caught
    stale = [dict(r) for r in stored]
    i = next(k for k, r in enumerate(stale) if (r["label"], r["controller"]) == ("case 1", "shif"))
    stale[i]["rmse_pitch_deg"] = math.nextafter(stale[i]["rmse_pitch_deg"], math.inf)
    j = next(k for k, r in enumerate(stale) if (r["label"], r["controller"]) == ("case 1", "lqr"))
    stale[j]["commands_sha256"] = stale[i]["commands_sha256"]
    diff = compare_records(stale, fresh)
    assert len(diff) == 2
    assert "rmse_pitch_deg" in diff[0] and "commands_sha256" in diff[1]
