"""What a campaign found: terminal summary, gates, ``report.html`` with PNGs, comparisons.

Figures (in the output folder):

- ``survival_heatmap.png``: survival per fault family x injection phase (rows) and
  controller (columns), with the counts;
- ``rotor_layout.png``: the lift rotors drawn where the airframe file puts them (top view,
  nose up) and coloured by the survival of the single-rotor-off scenarios, per controller;
- ``double_rotor_matrix.png``: 8 x 8 survival of every pair of lift rotors off (diagonal: the
  single rotor off), per controller;
- ``attitude_excursion.png``: distributions of the largest roll/pitch excursion per
  controller (a crash is at or beyond 60 deg).

Survival everywhere is :mod:`vtolftc.runners.campaign.outcome`.
"""

from __future__ import annotations

import html
import math
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from vtolftc.base.jsonio import atomic_write_text
from vtolftc.runners.campaign.outcome import ALTITUDE_TOLERANCE_M, ATTITUDE_TOLERANCE_DEG
from vtolftc.runners.campaign.results import TIMING_COLUMNS
from vtolftc.runners.campaign.spec import Gate

__all__ = ["check_gates", "compare", "recoverable_lines", "summary_lines", "worst",
           "write_report"]


def _rows(t: pa.Table) -> list[dict[str, Any]]:
    return t.to_pylist()


def _ordered(values: Sequence[str]) -> list[str]:
    seen: dict[str, None] = {}
    for v in values:
        seen.setdefault(v, None)
    return list(seen)


def survival_by(rows: Sequence[dict[str, Any]], *keys: str) -> dict[tuple[Any, ...], list[int]]:
    """{(key values): [survived, total]} in first-seen order."""
    out: dict[tuple[Any, ...], list[int]] = {}
    for r in rows:
        k = tuple(r[x] for x in keys)
        c = out.setdefault(k, [0, 0])
        c[0] += bool(r["survived"])
        c[1] += 1
    return out


def summary_lines(t: pa.Table) -> list[str]:
    """Survived x/n per family (rows) and controller (columns), as a Markdown table."""
    rows = _rows(t)
    ctls = _ordered([r["controller"] for r in rows])
    fams = _ordered([r["family"] for r in rows])
    s = survival_by(rows, "family", "controller")
    tot = survival_by(rows, "controller")
    lines = ["| family | " + " | ".join(ctls) + " |", "|---|" + "---:|" * len(ctls)]
    for f in fams:
        cells = []
        for c in ctls:
            k, n = s.get((f, c), [0, 0])
            cells.append(f"{k}/{n} ({100 * k / n:.0f} %)" if n else "—")
        lines.append(f"| {f} | " + " | ".join(cells) + " |")
    cells = []
    for c in ctls:
        k, n = tot.get((c,), [0, 0])
        cells.append(f"**{k}/{n} ({100 * k / n:.0f} %)**" if n else "—")
    lines.append("| all | " + " | ".join(cells) + " |")
    return lines


def recoverable_lines(t: pa.Table) -> list[str]:
    """Survival against the physical oracle, as a Markdown table: per family and phase, the
    flight conditions the oracle calls recoverable (of those judged) and, per controller,
    survived / recoverable (and how many unrecoverable ones it survived all the same).
    Empty when no row was judged (results written before the oracle)."""
    rows = [r for r in _rows(t) if r.get("recoverable") is not None
            and r.get("recovery_margin") is not None and math.isfinite(r["recovery_margin"])]
    if not rows:
        return []
    ctls = _ordered([r["controller"] for r in rows])
    cond: dict[tuple[str, str], dict[tuple[Any, ...], bool]] = defaultdict(dict)
    cnt: dict[tuple[str, str, str], list[int]] = defaultdict(lambda: [0, 0, 0])
    for r in rows:
        fp = (r["family"], r["phase"])
        cond[fp][(r["faults"], r["wind"], r["perturbation"], r["seed"])] = bool(
            r["recoverable"])
        c = cnt[(*fp, r["controller"])]
        if r["recoverable"]:
            c[0] += bool(r["survived"])
            c[1] += 1
        else:
            c[2] += bool(r["survived"])
    lines = ["| family | phase | recoverable | " + " | ".join(ctls) + " |",
             "|---|---|---:|" + "---:|" * len(ctls)]
    for fp, conds in cond.items():
        cells = []
        for ctl in ctls:
            k, n, extra = cnt.get((*fp, ctl), [0, 0, 0])
            cell = f"{k}/{n} ({100 * k / n:.0f} %)" if n else "—"
            if extra:
                cell += f", +{extra} unrecoverable survived"
            cells.append(cell)
        lines.append(f"| {fp[0]} | {fp[1]} | {sum(conds.values())}/{len(conds)} | "
                     + " | ".join(cells) + " |")
    return lines


def check_gates(gates: Sequence[Gate], t: pa.Table) -> list[str]:
    """One line per gate (family, controller) pair whose survival is below its minimum."""
    rows = _rows(t)
    s = survival_by(rows, "family", "controller")
    fams = _ordered([r["family"] for r in rows])
    ctls = _ordered([r["controller"] for r in rows])
    failed = []
    for g in gates:
        for f in [g.family] if g.family else fams:
            for c in [g.controller] if g.controller else ctls:
                k, n = s.get((f, c), [0, 0])
                if n and k / n < g.min_survival:
                    failed.append(f"gate: {c} survives {k}/{n} = {k / n:.1%} of family {f!r}, "
                                  f"below the minimum {g.min_survival:.1%}")
    return failed


def _worst_key(r: dict[str, Any]) -> tuple[Any, ...]:
    ct = r["crash_time_s"]
    crash_after = (ct - r["fault_time_s"]) if ct is not None and math.isfinite(ct) else math.inf
    exc = r["max_attitude_excursion_deg"]
    return (bool(r["survived"]), crash_after,
            -(exc if exc is not None and math.isfinite(exc) else 0.0))


def worst(t: pa.Table, n: int = 10) -> list[dict[str, Any]]:
    """The ``n`` worst scenarios: failures first, the fastest crash after injection first,
    then the largest attitude excursion."""
    return sorted(_rows(t), key=_worst_key)[:n]


def _fmt(v: Any, nd: int = 2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    return f"{v:.{nd}f}" if isinstance(v, float) else str(v)


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------

def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _heatmap(rows: list[dict[str, Any]], path: Path) -> None:
    plt = _plt()
    ctls = _ordered([r["controller"] for r in rows])
    keys = _ordered([(r["family"], r["phase"]) for r in rows])
    s = survival_by(rows, "family", "phase", "controller")
    M = np.full((len(keys), len(ctls)), np.nan)
    for i, (f, p) in enumerate(keys):
        for j, c in enumerate(ctls):
            k, n = s.get((f, p, c), [0, 0])
            if n:
                M[i, j] = k / n
    fig, ax = plt.subplots(figsize=(2.0 + 1.6 * len(ctls), 1.0 + 0.32 * len(keys)))
    im = ax.imshow(M, cmap="RdYlGn", vmin=0.0, vmax=1.0, aspect="auto")
    for i, (f, p) in enumerate(keys):
        for j, c in enumerate(ctls):
            k, n = s.get((f, p, c), [0, 0])
            if n:
                ax.text(j, i, f"{k}/{n}", ha="center", va="center", fontsize=7)
    ax.set_xticks(range(len(ctls)), ctls)
    ax.set_yticks(range(len(keys)), [f"{f} @ {p}" for f, p in keys], fontsize=7)
    ax.xaxis.tick_top()
    fig.colorbar(im, ax=ax, label="survival")
    ax.set_title("survival per fault family x phase x controller", fontsize=9, pad=22)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _single_double(rows: list[dict[str, Any]], rotors: Sequence[str],
                   ) -> tuple[dict[Any, list[int]], dict[Any, list[int]]]:
    """Survival of single and double lift-rotor-off sets: {(ctl, rotor)} and
    {(ctl, rotor_i, rotor_j)} -> [survived, total]."""
    single: dict[Any, list[int]] = defaultdict(lambda: [0, 0])
    double: dict[Any, list[int]] = defaultdict(lambda: [0, 0])
    rs = set(rotors)
    for r in rows:
        parts = r["faults"].split("+") if "+" in r["faults"] else r["faults"].split(" ")
        acts = []
        for p in parts:
            a, _, kind = p.partition(":")
            if kind != "off" or a not in rs:
                acts = []
                break
            acts.append(a)
        if len(acts) == 1:
            c = single[(r["controller"], acts[0])]
        elif len(acts) == 2:
            c = double[(r["controller"], *sorted(acts, key=list(rotors).index))]
        else:
            continue
        c[0] += bool(r["survived"])
        c[1] += 1
    return single, double


def _rotor_layout(rows: list[dict[str, Any]], airframe: Any, path: Path) -> bool:
    plt = _plt()
    from matplotlib.patches import Circle

    names = [f"rotor_{r.name}" for r in airframe.lift_rotors]
    single, _ = _single_double(rows, names)
    ctls = _ordered([c for c, _ in single])
    if not ctls:
        return False
    cmap = plt.get_cmap("RdYlGn")
    fig, axes = plt.subplots(1, len(ctls), figsize=(3.4 * len(ctls), 3.8), squeeze=False)
    pos = np.array([r.position_m for r in airframe.lift_rotors])
    span = airframe.wing.span_m
    rad = 0.12 * max(np.ptp(pos[:, 0]), np.ptp(pos[:, 1]), 0.5)
    for ax, c in zip(axes[0], ctls, strict=True):
        ax.plot([-span / 2, span / 2], [0, 0], color="0.7", lw=6, solid_capstyle="round")
        ax.plot([0, 0], [pos[:, 0].min() - rad, pos[:, 0].max() + rad], color="0.7", lw=4)
        for rot, (x, y, _z) in zip(airframe.lift_rotors, pos, strict=True):
            k, n = single.get((c, f"rotor_{rot.name}"), [0, 0])
            col = cmap(k / n) if n else (0.85, 0.85, 0.85, 1.0)
            ax.add_patch(Circle((y, x), rad, facecolor=col, edgecolor="k"))
            ax.text(y, x, f"{rot.name}\n{k}/{n}" if n else rot.name, ha="center",
                    va="center", fontsize=7)
        ax.set_aspect("equal")
        ax.set_xlim(min(-span / 2, pos[:, 1].min() - rad) - 0.1,
                    max(span / 2, pos[:, 1].max() + rad) + 0.1)
        ax.set_ylim(pos[:, 0].min() - 2 * rad, pos[:, 0].max() + 2 * rad)
        ax.set_title(f"{c}: one rotor off", fontsize=9)
        ax.set_xlabel("y right (m)")
        ax.set_ylabel("x forward (m)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


def _double_matrix(rows: list[dict[str, Any]], airframe: Any, path: Path) -> bool:
    plt = _plt()
    names = [f"rotor_{r.name}" for r in airframe.lift_rotors]
    single, double = _single_double(rows, names)
    ctls = _ordered([k[0] for k in double])
    if not ctls:
        return False
    n = len(names)
    fig, axes = plt.subplots(1, len(ctls), figsize=(3.6 * len(ctls), 3.6), squeeze=False)
    for ax, c in zip(axes[0], ctls, strict=True):
        M = np.full((n, n), np.nan)
        for i in range(n):
            for j in range(n):
                if i == j:
                    k, m = single.get((c, names[i]), [0, 0])
                else:
                    a, b = sorted((i, j))
                    k, m = double.get((c, names[a], names[b]), [0, 0])
                if m:
                    M[i, j] = k / m
        ax.imshow(M, cmap="RdYlGn", vmin=0, vmax=1)
        for i in range(n):
            for j in range(n):
                if math.isfinite(M[i, j]):
                    ax.text(j, i, f"{M[i, j]:.0%}", ha="center", va="center", fontsize=6)
        lab = [x.removeprefix("rotor_") for x in names]
        ax.set_xticks(range(n), lab, fontsize=7)
        ax.set_yticks(range(n), lab, fontsize=7)
        ax.set_title(f"{c}: two rotors off", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


def _excursions(rows: list[dict[str, Any]], path: Path) -> None:
    plt = _plt()
    ctls = _ordered([r["controller"] for r in rows])
    fig, ax = plt.subplots(figsize=(6, 3.2))
    bins = np.linspace(0, 90, 46)
    for c in ctls:
        v = [min(r["max_attitude_excursion_deg"], 89.9) for r in rows
             if r["controller"] == c and r["max_attitude_excursion_deg"] is not None
             and math.isfinite(r["max_attitude_excursion_deg"])]
        ax.hist(v, bins=bins, histtype="step", lw=1.5, label=f"{c} (n = {len(v)})")
    ax.axvline(ATTITUDE_TOLERANCE_DEG, color="0.5", ls=":", lw=1)
    ax.axvline(60, color="r", ls="--", lw=1, label="crash (60 deg)")
    ax.set_xlabel("largest |roll| or |pitch| after injection (deg)")
    ax.set_ylabel("scenarios")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_report(out_dir: str | Path, t: pa.Table, *, title: str, description: str = "",
                 airframe: Any = None, gate_failures: Sequence[str] = ()) -> Path:
    """Write ``report.html`` and its PNGs into ``out_dir``; return the HTML path."""
    out = Path(out_dir)
    rows = _rows(t)
    figs = []
    _heatmap(rows, out / "survival_heatmap.png")
    figs.append(("survival_heatmap.png", "Survival per fault family x phase x controller"))
    if airframe is not None:
        if _rotor_layout(rows, airframe, out / "rotor_layout.png"):
            figs.append(("rotor_layout.png", "Single lift rotor off: survival per rotor"))
        if _double_matrix(rows, airframe, out / "double_rotor_matrix.png"):
            figs.append(("double_rotor_matrix.png", "Two lift rotors off: survival per pair"))
    _excursions(rows, out / "attitude_excursion.png")
    figs.append(("attitude_excursion.png", "Largest attitude excursion after injection"))

    def md_table(lines: list[str]) -> str:
        cells = [[c.strip().strip("*") for c in ln.strip("|").split("|")] for ln in lines]
        head, body = cells[0], cells[2:]
        h = "".join(f"<th>{html.escape(c)}</th>" for c in head)
        b = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>"
                    for r in body)
        return f"<table><tr>{h}</tr>{b}</table>"

    w = worst(t, 15)
    wrows = "".join(
        f"<tr><td>{html.escape(r['controller'])}</td><td>{html.escape(r['family'])}</td>"
        f"<td>{html.escape(r['faults'])}</td><td>{html.escape(r['phase'])}</td>"
        f"<td>{html.escape(r['wind'])}</td><td>{html.escape(r['outcome'])}</td>"
        f"<td>{_fmt(r['crash_time_s'])}</td><td>{_fmt(r['max_attitude_excursion_deg'], 1)}</td>"
        f"<td><code>{html.escape(r['fly_command'])}</code></td></tr>" for r in w)
    gates = "".join(f"<li>{html.escape(g)}</li>" for g in gate_failures)
    from vtolftc.firmware_sim.vehicle.recoverability import RECOVERABLE_MIN_MARGIN

    rec = recoverable_lines(t)
    oracle = ("<h2>Survived / recoverable per family and phase</h2><p>Recoverable: the "
              "actuators left can hold the trim at the scenario's flight condition with a "
              f"moment reserve about every axis (margin >= {RECOVERABLE_MIN_MARGIN:g} "
              "rad/s^2; the physical "
              "oracle, <code>vtolftc.firmware_sim.vehicle.recoverability</code>); the "
              "recoverable column counts flight conditions, the controller columns "
              "survived / recoverable scenarios.</p>" + md_table(rec)) if rec else ""
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;max-width:1200px;margin:2em auto}}
table{{border-collapse:collapse;font-size:13px}}td,th{{border:1px solid #ccc;padding:3px 6px}}
code{{font-size:11px}}</style></head><body>
<h1>{html.escape(title)}</h1><p>{html.escape(description)}</p>
<p>{len(rows)} scenarios. Survived = no crash and, at the end, altitude within
{ALTITUDE_TOLERANCE_M:g} m of its reference and roll and pitch (mean over the last second)
within {ATTITUDE_TOLERANCE_DEG:g} deg of level.</p>
{"<h2>Gates failed</h2><ul>" + gates + "</ul>" if gates else ""}
<h2>Survival per family and controller</h2>{md_table(summary_lines(t))}
{oracle}
{"".join(f'<h2>{html.escape(c)}</h2><img src="{f}" alt="{html.escape(c)}">' for f, c in figs)}
<h2>Worst scenarios</h2><table><tr><th>controller</th><th>family</th><th>faults</th>
<th>phase</th><th>wind</th><th>outcome</th><th>crash (s)</th><th>max excursion (deg)</th>
<th>re-fly</th></tr>{wrows}</table></body></html>
"""
    return atomic_write_text(out / "report.html", doc)


# --------------------------------------------------------------------------------------------
# Comparison of two result files
# --------------------------------------------------------------------------------------------

def compare(a: pa.Table, b: pa.Table, name_a: str = "A", name_b: str = "B") -> list[str]:
    """What changed from ``a`` to ``b``, scenario by scenario (matched by scenario id)."""
    ra = {r["scenario_id"]: r for r in _rows(a)}
    rb = {r["scenario_id"]: r for r in _rows(b)}
    common = [k for k in ra if k in rb]
    only_a = [k for k in ra if k not in rb]
    only_b = [k for k in rb if k not in ra]
    lines = [f"{name_a}: {len(ra)} scenarios, {name_b}: {len(rb)}; {len(common)} in both, "
             f"{len(only_a)} only in {name_a}, {len(only_b)} only in {name_b}"]
    sa = sum(bool(ra[k]["survived"]) for k in common)
    sb = sum(bool(rb[k]["survived"]) for k in common)
    lines.append(f"survived (common scenarios): {name_a} {sa}/{len(common)}, "
                 f"{name_b} {sb}/{len(common)}")
    changed, differ = [], 0
    skip = {"index", "fly_command", *TIMING_COLUMNS}
    for k in common:
        x, y = ra[k], rb[k]
        if x["outcome"] != y["outcome"]:
            changed.append((x, y))
        if any(not _same(x[c], y[c]) for c in x if c not in skip):
            differ += 1
    lines.append(f"outcome changed in {len(changed)} scenarios; any metric changed in {differ}")
    for x, y in changed:
        lines.append(f"  {x['scenario_id']} {x['controller']:7s} {x['family']} {x['faults']} "
                     f"@ {x['phase']} wind={x['wind']} pert={x['perturbation']} seed={x['seed']}"
                     f": {x['outcome']} -> {y['outcome']}")
    for label, ks, src in ((f"only in {name_a}", only_a, ra), (f"only in {name_b}", only_b, rb)):
        for k in ks[:20]:
            r = src[k]
            lines.append(f"  {label}: {k} {r['controller']} {r['family']} {r['faults']} "
                         f"@ {r['phase']}: {r['outcome']}")
        if len(ks) > 20:
            lines.append(f"  ... and {len(ks) - 20} more {label}")
    return lines


def _same(u: Any, v: Any) -> bool:
    if isinstance(u, float) and isinstance(v, float):
        return (math.isnan(u) and math.isnan(v)) or u == v
    return bool(u == v)
