"""Tables and plots of the flight re-measurement (reads the JSON files of ``measure.py``).

    python docs/ds1-claims/tables.py     # prints markdown, writes rmse.png and survival.png

Inputs in this folder: ``table3.json`` (mu and delay margins from the gain files),
``robust.json``, ``paper.json`` (``measure.py --label ...``),
optionally ``robust-gs-shif.json`` (GS-SHIF survival of the robust design) and
``*-delay.json``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent


def load(name: str) -> list[dict[str, Any]]:
    p = HERE / f"{name}.json"
    return json.loads(p.read_text()) if p.is_file() else []


def table3(recs: list[dict[str, Any]]) -> str:
    """Table 3 of both designs side by side (``table3.json``)."""
    cell = {(r["design"], r["axis"], r["point"]): r for r in recs}
    out = ["| axis | No. | paper mu_Delta | paper mu_Delta-hat | robust mu_Delta | "
           "robust mu_Delta-hat | robust delay margin [ms] | paper delay margin [ms] |",
           "|---|---|---:|---:|---:|---:|---:|---:|"]
    points = sorted({(r["axis"], r["point"], r["airspeed_m_s"]) for r in recs},
                    key=lambda k: (("roll", "pitch", "yaw").index(k[0]), k[1]))
    for ax, n, v in points:
        p, r = cell.get(("paper", ax, n)), cell.get(("robust", ax, n))

        def f(x: dict[str, Any] | None, k: str, fmt: str = ".3f") -> str:
            return "-" if x is None else format(x[k], fmt)

        no = f"{n} ({v:g} m/s)" if p is None else str(n)
        out.append(f"| {ax} | {no} | {f(p, 'mu_rs')} | {f(p, 'mu_rp')} | {f(r, 'mu_rs')} | "
                   f"{f(r, 'mu_rp')} | {f(r, 'delay_margin_ms', '.0f')} | "
                   f"{f(p, 'delay_margin_ms', '.0f')} |")
    return "\n".join(out)


def table4(rows: dict[str, list[dict[str, Any]]]) -> str:
    out = ["| design | case | controller | roll RMSE [deg] | pitch RMSE [deg] | "
           "yaw RMSE [deg] | altitude RMSE [m] | crashed |",
           "|---|---|---|---:|---:|---:|---:|---|"]
    for design, rs in rows.items():
        for r in rs:
            if not r["label"].startswith("case"):
                continue
            out.append(f"| {design} | {r['label'][5:]} | {r['controller']} | "
                       f"{r['rmse_roll_deg']:.3f} | {r['rmse_pitch_deg']:.3f} | "
                       f"{r['rmse_yaw_deg']:.3f} | {r['rmse_altitude_m']:.3f} | "
                       f"{r['crashed']} |")
    return "\n".join(out)


def survival(rows: dict[str, list[dict[str, Any]]]) -> str:
    cols: list[tuple[str, str]] = []
    cells: dict[tuple[str, str], dict[str, Any]] = {}
    labels: list[str] = []
    for design, rs in rows.items():
        for r in rs:
            if r["label"].startswith("case") or r["label"].startswith("delay"):
                continue
            key = (design, r["controller"])
            if key not in cols:
                cols.append(key)
            if r["label"] not in labels:
                labels.append(r["label"])
            cells[(r["label"], f"{design}/{r['controller']}")] = r
    head = "| fault | " + " | ".join(f"{d} {c}" for d, c in cols) + " |"
    out = [head, "|---|" + "---|" * len(cols)]
    for lab in labels:
        row = [lab]
        for d, c in cols:
            r = cells.get((lab, f"{d}/{c}"))
            if r is None:
                row.append("-")
            elif r["survived"]:
                if "peak_roll_deg" in r:
                    row.append(f"ok ({r['peak_roll_deg']:.0f}/{r['peak_pitch_deg']:.0f} deg)")
                else:
                    row.append("ok")
            else:
                why = (f"crash {r['crash_time_s']:.1f} s" if r["crashed"]
                       else f"alt err {r['final_altitude_error_m']:.0f} m")
                row.append(f"LOST ({why})")
        out.append("| " + " | ".join(row) + " |")
    tot = ["**survived**"]
    for d, c in cols:
        rs = [cells[(lab, f"{d}/{c}")] for lab in labels if (lab, f"{d}/{c}") in cells]
        tot.append(f"**{sum(r['survived'] for r in rs)}/{len(rs)}**")
    out.append("| " + " | ".join(tot) + " |")
    return "\n".join(out)


def delay_table(rows: dict[str, list[dict[str, Any]]]) -> str:
    out = ["| design | one-way HIL delay | crashed | transition complete [s] | "
           "peak pitch / roll, whole flight [deg] | max pitch error t >= 20 s [deg] | "
           "pitch RMSE t >= 20 s [deg] | final altitude error [m] |",
           "|---|---|---|---:|---:|---:|---:|---:|"]
    for design, rs in rows.items():
        for r in rs:
            tc = r["transition_complete_s"]
            pk = (f"{r['peak_pitch_deg']:.1f} / {r['peak_roll_deg']:.1f}"
                  if "peak_pitch_deg" in r else "-")
            out.append(f"| {design} | {r['label'][6:]} | {r['crashed']} | "
                       f"{'-' if tc is None else f'{tc:.2f}'} | {pk} | "
                       f"{r['max_abs_pitch_error_deg']:.2f} | {r['rmse_pitch_deg']:.3f} | "
                       f"{r['final_altitude_error_m']:.2f} |")
    return "\n".join(out)


def plot_rmse(rows: dict[str, list[dict[str, Any]]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for a, case in zip(axs, ("1", "2"), strict=True):
        bars, names = [], []
        for design, rs in rows.items():
            for r in rs:
                if r["label"] == f"case {case}":
                    names.append(f"{design}\n{r['controller']}")
                    bars.append((r["rmse_roll_deg"], r["rmse_pitch_deg"], r["rmse_yaw_deg"]))
        x = range(len(names))
        for k, (lab, off) in enumerate((("roll", -0.27), ("pitch", 0.0), ("yaw", 0.27))):
            a.bar([i + off for i in x], [b[k] for b in bars], width=0.27, label=lab)
        a.set_xticks(list(x), names, fontsize=7)
        a.set_title(f"paper case {case}: RMSE over t >= 20 s")
        a.grid(True, axis="y", alpha=0.3)
    axs[0].set_ylabel("RMSE [deg]")
    axs[0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> int:
    t4 = {"paper": load("paper"), "robust": load("robust")}
    sv = {"paper": load("paper"), "robust": load("robust") + load("robust-gs-shif")}
    dl = {"paper": load("paper-delay") + load("paper-delay-long"),
          "robust": load("robust-delay") + load("robust-delay-long")}
    t3 = load("table3")
    if t3:
        print("## Table 3\n\n" + table3(t3) + "\n")
    print("## Table 4\n\n" + table4(t4) + "\n")
    print("## Single-fault survival\n\n" + survival(sv) + "\n")
    if any(dl.values()):
        print("## One-way HIL delay\n\n" + delay_table(dl) + "\n")
    plot_rmse(t4, HERE / "rmse.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
