"""Does the yaw predictor rank the flown yaw RMSE? (issue 23, items 1-2; session 12).

Flies the paper's cases 1 and 2 in-process with gain sets that differ only in yaw: the
surface2 GS-SHIF (``firmware_sim/autopilot/gains/surface2/gs-shif.json``) with its yaw gains
replaced by the constant yaw gains of the paper, shipped robust, surface and surface2 SHIFs,
and scaled (ki_rate, kp_angle, kp_rate with kd_rate, all together); and a cross set (the
paper SHIF's roll and pitch with surface2's GS-SHIF yaw; with "yaw of paper SHIF", surface2's
roll and pitch with the paper SHIF's yaw, it shows where the paper's flown yaw error comes
from). Prints, per
flight, the predicted yaw RMSE, single-axis
(:func:`~vtolftc.synthesis.fault_objective.predicted_rmse`) and with the roll-sideslip-yaw
coupling (:func:`~vtolftc.synthesis.lateral_objective.lateral_yaw_rmse`), each at
:data:`~vtolftc.synthesis.fault_objective.CASE_AIRSPEEDS` and at
:data:`~vtolftc.synthesis.fault_objective.FLOWN_CASE_AIRSPEEDS`, against the flown one;
Spearman's rank correlation over the yaw-only sets per case and over every flight (with the
14 flights of the 7 controllers of ``docs/ds1-surfaces/results.json``); the share of the
squared yaw error per time window and the flown airspeed after the fault go to the file;
writes
``docs/ds1-surfaces/surface2/yaw.json``::

    python benchmarks/yaw_ranking.py [--jobs 2]

Each flight takes ~1 s CPU once numba's cache is warm (40 s wall for the 26 flights, 2
workers, load ~7).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GAINS = ROOT / "firmware_sim" / "autopilot" / "gains"
OUT = ROOT / "docs" / "ds1-surfaces" / "surface2" / "yaw.json"
NAMES = ("kp_angle", "kp_rate", "ki_rate", "kd_rate", "tf_rate_s")
#: Time windows [s] of the yaw error's decomposition (fault at 22 s, transition from 20 s).
WINDOWS = ((20.0, 22.0), (22.0, 23.0), (23.0, 24.0), (24.0, 26.0), (26.0, 28.0),
           (28.0, 40.0))


def _doc(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text(encoding="utf-8"))


def _constant_yaw(path: Path) -> dict[str, float]:
    return {k: float(_doc(path)["axes"]["yaw"][k][0]) for k in NAMES}


def gain_sets(tmp: Path) -> dict[str, tuple[str, bool]]:
    """name -> (gains directory holding a gs-shif.json, yaw-only change of surface2)."""
    base = _doc(GAINS / "surface2" / "gs-shif.json")
    paper = _doc(GAINS / "paper" / "shif.json")

    def write(name: str, doc: dict[str, Any]) -> str:
        d = tmp / name
        d.mkdir()
        (d / "gs-shif.json").write_text(json.dumps(doc), encoding="utf-8")
        return str(d)

    def yaw_set(name: str, yaw: dict[str, float] | None = None,
                scale: dict[str, float] | None = None) -> str:
        doc = copy.deepcopy(base)
        n = len(doc["airspeed_breakpoints_m_s"])
        ax = doc["axes"]["yaw"]
        if yaw is not None:
            for k in NAMES:
                ax[k] = [yaw[k]] * n
        for k, s in (scale or {}).items():
            ax[k] = [x * s for x in ax[k]]
        return write(name, doc)

    sets = {"surface2 GS-SHIF": (yaw_set("base"), True)}
    for label, f in (("paper SHIF", "paper/shif.json"), ("robust SHIF", "shif.json"),
                     ("surface SHIF", "surface/shif.json"),
                     ("surface2 SHIF", "surface2/shif.json")):
        sets[f"yaw of {label}"] = (yaw_set(label.replace(" ", "_"), _constant_yaw(GAINS / f)),
                                   True)
    for label, sc in (("ki_rate x2", {"ki_rate": 2.0}), ("ki_rate x0.5", {"ki_rate": 0.5}),
                      ("kp_angle x1.5", {"kp_angle": 1.5}),
                      ("kp_angle x0.7", {"kp_angle": 0.7}),
                      ("kp_rate, kd_rate x1.5", {"kp_rate": 1.5, "kd_rate": 1.5}),
                      ("kp_rate, kd_rate x0.7", {"kp_rate": 0.7, "kd_rate": 0.7}),
                      ("all up", {"kp_rate": 2.0, "kd_rate": 2.0, "ki_rate": 4.0,
                                  "kp_angle": 1.5})):
        sets[f"yaw {label}"] = (yaw_set(label.replace(" ", "_").replace(",", ""),
                                        scale=sc), True)
    # cross sets: the paper SHIF's roll and pitch with surface2's yaw, and the paper itself
    cross = copy.deepcopy(base)
    for ax in ("roll", "pitch"):
        for k in NAMES:
            cross["axes"][ax][k] = [paper["axes"][ax][k][0]] * len(
                cross["airspeed_breakpoints_m_s"])
    sets["paper SHIF roll/pitch, surface2 GS-SHIF yaw"] = (write("cross", cross), False)
    return sets


def fly(args: tuple[str, str, int]) -> dict[str, Any]:
    """One flight: metrics, yaw-error shares per window, airspeeds after the fault."""
    from vtolftc.runners.scenario import paper_scenario, run_scenario

    name, gdir, case = args

    class Rec:
        def __init__(self) -> None:
            self.rows: list[list[float]] = []

        def on_start(self, info: dict[str, Any]) -> None:
            pass

        def on_event(self, t: int, kind: str, text: str) -> None:
            pass

        def on_finish(self, m: dict[str, Any]) -> None:
            pass

        def on_sample(self, s: Any) -> None:
            st = s.status
            self.rows.append([s.time_usec * 1e-6, *st.attitude_ref_rad, *st.attitude_rad,
                              st.airspeed_m_s])

    rec = Rec()
    m = run_scenario(paper_scenario(case), "gs-shif", gains_dir=gdir, observers=[rec]).metrics
    a = np.array(rec.rows)
    t = a[:, 0]
    e = np.degrees(a[:, 1:4] - a[:, 4:7])
    e[:, 2] = (e[:, 2] + 180.0) % 360.0 - 180.0
    tot = float(np.sum(e[t >= 20.0, 2] ** 2))
    shares = {f"{lo:g}-{hi:g} s": float(np.sum(e[(t >= lo) & (t < hi), 2] ** 2) / tot)
              for lo, hi in WINDOWS}
    return {"set": name, "case": case, "rmse_roll_deg": m["rmse_roll_deg"],
            "rmse_pitch_deg": m["rmse_pitch_deg"], "rmse_yaw_deg": m["rmse_yaw_deg"],
            "crashed": m["crashed"], "yaw_share": shares,
            "airspeed_m_s": {f"{x:g} s": float(np.interp(x, t, a[:, 7]))
                             for x in (22.0, 22.5, 23.5, 24.5, 25.5)}}


#: The controllers of ``docs/ds1-surfaces/results.json`` (flown with the same code) and
#: their gain files.
EARLIER = {"robust GS-SHIF": "gs-shif.json", "robust SHIF": "shif.json", "LQR": "lqr.json",
           "paper GS-SHIF": "paper/gs-shif.json", "paper SHIF": "paper/shif.json",
           "surface GS-SHIF": "surface/gs-shif.json", "surface SHIF": "surface/shif.json"}


def predict(gfile: str, case: int) -> dict[str, float]:
    """Predicted yaw RMSE [deg]: single-axis (fault_objective) and roll-sideslip-yaw
    (lateral_objective), each at the design and at the flown airspeeds."""
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.synthesis.fault_objective import (
        CASE_AIRSPEEDS,
        FLOWN_CASE_AIRSPEEDS,
        controller_from_document,
        paper_cases,
        predicted_rmse,
    )
    from vtolftc.synthesis.lateral_objective import lateral_yaw_rmse

    af = load_airframe()
    doc = _doc(Path(gfile))
    yaw = controller_from_document(doc, "yaw")
    roll = controller_from_document(doc, "roll")
    out = {}
    for label, v in (("design", CASE_AIRSPEEDS), ("flown", FLOWN_CASE_AIRSPEEDS)):
        c = paper_cases(v)[str(case)]
        out[f"single {label}"] = math.degrees(predicted_rmse(af, "yaw", yaw, c))
        out[f"lateral {label}"] = math.degrees(lateral_yaw_rmse(af, roll, yaw, c))
    return out


def _spearman(rows: list[dict[str, Any]], key: str) -> dict[str, Any]:
    """Spearman's rho of predicted (``key``) against flown yaw RMSE, all and finite only
    (a loop the linear model calls unstable predicts inf: ranked worst in "all")."""
    from scipy.stats import spearmanr

    pred = [r["pred_yaw_deg"][key] for r in rows]
    flown = [r["rmse_yaw_deg"] for r in rows]
    fin = [i for i, p in enumerate(pred) if math.isfinite(p)]
    return {"all": float(spearmanr(pred, flown)[0]),
            "finite": float(spearmanr([pred[i] for i in fin], [flown[i] for i in fin])[0]),
            "n": len(rows), "n_finite": len(fin)}


def _finite(x: Any) -> Any:
    """Non-finite floats as null (strict JSON: a loop the linear model calls unstable)."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_finite(v) for v in x]
    return x


def main(argv: list[str] | None = None) -> int:
    """Fly, predict, rank, print and write ``yaw.json``; returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args(argv)
    if a.jobs < 1:
        print("yaw_ranking: expected --jobs >= 1", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as td:
        sets = gain_sets(Path(td))
        jobs = [(n, g, c) for n, (g, _) in sets.items() for c in (1, 2)]
        with ProcessPoolExecutor(a.jobs) as ex:
            rows = list(ex.map(fly, jobs))
        for r in rows:
            r["pred_yaw_deg"] = predict(str(Path(sets[r["set"]][0]) / "gs-shif.json"),
                                        r["case"])
            r["yaw_only"] = sets[r["set"]][1]
    earlier = _doc(ROOT / "docs" / "ds1-surfaces" / "results.json")["rows"]
    for e in earlier:
        rows.append({"set": e["controller"], "case": int(e["case"]),
                     "rmse_roll_deg": e["rmse_roll_deg"], "rmse_yaw_deg": e["rmse_yaw_deg"],
                     "source": "docs/ds1-surfaces/results.json", "yaw_only": False,
                     "pred_yaw_deg": predict(str(GAINS / EARLIER[e["controller"]]),
                                             int(e["case"]))})
    keys = ("single design", "single flown", "lateral design", "lateral flown")
    out: dict[str, Any] = {"rows": rows, "spearman": {}}
    for c in (1, 2):
        yo = [r for r in rows if r["case"] == c and r["yaw_only"]]
        for k in keys:
            out["spearman"][f"case {c}, yaw-only sets, {k}"] = _spearman(yo, k)
    for k in keys:
        out["spearman"][f"every flight, {k}"] = _spearman(rows, k)
    for r in rows:
        p = r["pred_yaw_deg"]
        print(f"case {r['case']} {r['set']:45s} flown yaw {r['rmse_yaw_deg']:.3f} roll "
              f"{r['rmse_roll_deg']:.3f} pred " + " ".join(f"{p[k]:.3f}" for k in keys))
    print(json.dumps(out["spearman"], indent=1))
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(_finite(out), indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
