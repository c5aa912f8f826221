"""The certify report: one self-contained ``report.html`` (pictures inlined as PNG).

First the verdict of every stage and the gates, then the three pictures a reader looks at
first (campaign survival against the recoverability oracle per family and phase, the mixed-mu
upper bound against airspeed, the SITL mission's track), then the tables and every failure
with the exact command that re-flies it.
"""

from __future__ import annotations

import base64
import html
import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["write_report"]

_COLOURS = {"pass": "#1a7f37", "fail": "#cf222e", "skipped": "#9a6700"}


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    _plt().close(fig)
    return ('<img alt="figure" src="data:image/png;base64,'
            + base64.b64encode(buf.getvalue()).decode() + '">')


def survival_figure(camp: Mapping[str, Any]) -> str:
    """Bars per (family, phase): scenarios, recoverable (oracle), survived of those."""
    cells = camp.get("cells") or {}
    if not cells:
        return ""
    plt = _plt()
    names = list(cells)
    x = range(len(names))
    fig, ax = plt.subplots(figsize=(max(5.0, 0.9 * len(names) + 2), 3.4))
    ax.bar([i - 0.27 for i in x], [cells[n]["scenarios"] for n in names], 0.27,
           label="scenarios", color="#d0d7de")
    ax.bar(list(x), [cells[n]["recoverable"] for n in names], 0.27,
           label="recoverable (oracle)", color="#54aeff")
    ax.bar([i + 0.27 for i in x], [cells[n]["survived_recoverable"] for n in names], 0.27,
           label="survived of recoverable", color="#1a7f37")
    ax.set_xticks(list(x), [n.replace("|", "\n") for n in names], fontsize=7)
    ax.set_ylabel("scenarios")
    ax.set_title("GS-SHIF survival against the recoverability oracle")
    ax.legend(fontsize=7)
    return _png(fig)


def mu_figure(cert: Mapping[str, Any]) -> str:
    """The mixed-mu upper bound of each axis over each design point's airspeed range."""
    rows = cert.get("rows") or []
    if not rows:
        return ""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.0, 3.2))
    colours = {"roll": "#0969da", "pitch": "#bf3989", "yaw": "#9a6700"}
    seen: set[str] = set()
    top = 1.5
    for r in rows:
        mu = r["mu_upper"] if r["mu_upper"] is not None else 10.0
        top = max(top, min(mu, 10.0) * 1.1)
        ax.plot([r["v_min_m_s"], r["v_max_m_s"]], [mu, mu], lw=3,
                color=colours.get(r["axis"], "k"),
                label=None if r["axis"] in seen else r["axis"])
        seen.add(r["axis"])
    ax.axhline(1.0, color="#cf222e", ls="--", lw=1, label="mu = 1")
    ax.set_ylim(0, top)
    ax.set_xlabel("airspeed (m/s)")
    ax.set_ylabel("mixed mu upper bound")
    ax.set_title("Robust stability over airspeed x loss of effectiveness")
    ax.legend(fontsize=7)
    return _png(fig)


def track_figure(sitl: Mapping[str, Any]) -> str:
    """The SITL mission's ground track (north up), fixed-wing parts highlighted, home."""
    tr = sitl.get("track_ne_m") or []
    if not tr:
        return ""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.0, 4.0))
    n = [p[0] for p in tr]
    e = [p[1] for p in tr]
    ax.plot(e, n, color="#57606a", lw=1, label="track")
    fw = sitl.get("fw") or []
    if fw and len(fw) == len(tr):
        ax.scatter([x for x, f in zip(e, fw, strict=True) if f],
                   [y for y, f in zip(n, fw, strict=True) if f], s=2, color="#0969da",
                   label="fixed-wing")
    ax.plot([0], [0], "k^", label="home")
    ax.plot([e[-1]], [n[-1]], "ro", ms=4, label="landed")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title("SITL mission over UDP")
    ax.legend(fontsize=7)
    return _png(fig)


def _table(head: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    h = "".join(f"<th>{html.escape(str(c))}</th>" for c in head)
    b = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                for r in rows)
    return f"<table><tr>{h}</tr>{b}</table>"


def _num(x: Any, nd: int = 2) -> str:
    return "—" if x is None else f"{x:.{nd}f}" if isinstance(x, float) else str(x)


def _stage_section(name: str, rec: Mapping[str, Any]) -> str:
    parts = []
    if name == "trim":
        parts.append(_table(("V (m/s)", "mode", "pitch (deg)", "elevator (deg)", "pusher (%)",
                             "rotor lift share (%)", "CL"),
                            [(r["airspeed_m_s"], r["mode"], _num(r.get("pitch_deg")),
                              _num(r.get("elevator_deg")), _num(r.get("pusher_pct"), 1),
                              _num(r.get("rotor_lift_share_pct"), 1),
                              _num(r.get("CL"), 3)) if r["feasible"]
                             else (r["airspeed_m_s"], r["mode"], "infeasible", r.get("note"),
                                   "", "", "") for r in rec.get("rows", [])]))
    elif name == "synth":
        rows = [(ax, d["label"], "yes" if d["stable"] else "NO", _num(d["gamma"], 3))
                for ax, ds in rec.get("designs", {}).items() for d in ds]
        parts.append(f"<p>gain files in <code>{html.escape(str(rec.get('gains_dir')))}"
                     "</code></p>")
        parts.append(_table(("axis", "design point", "nominally stable", "gamma"), rows))
    elif name == "certificate":
        parts.append(f"<p>{rec.get('certified')} of {rec.get('claimed')} claimed axis-points "
                     "certified (mixed mu upper bound &lt; 1).</p>")
        parts.append(_table(("axis", "point", "airspeeds (m/s)", "mu upper", "mu lower",
                             "verdict"),
                            [(r["axis"], r["point"], f"{r['v_min_m_s']:g}-{r['v_max_m_s']:g}",
                              _num(r["mu_upper"], 3), _num(r["mu_lower"], 3), r["verdict"])
                             for r in rec.get("rows", [])]))
    elif name == "campaign":
        parts.append(f"<p>GS-SHIF survived {rec.get('survived')} of {rec.get('scenarios')} "
                     "scenarios.</p>")
        parts.append(_table(("gate", "survived / recoverable", "minimum", "verdict"),
                            [(g["name"], f"{g['survived']}/{g['recoverable']}",
                              f"{g['min']:.0%}",
                              (f"pass, vacuously (none of {g['flown']} flown recoverable)"
                               if g.get("flown") else "n/a (none in this profile)")
                              if not g["recoverable"]
                              else "pass" if g["pass"] else "FAIL")
                             for g in rec.get("gates", [])]))
        parts.append(_table(("family", "phase", "scenarios", "recoverable", "survived",
                             "survived of recoverable"),
                            [(*k.split("|"), c["scenarios"], c["recoverable"], c["survived"],
                              c["survived_recoverable"])
                             for k, c in rec.get("cells", {}).items()]))
    elif name == "sitl":
        parts.append(f"<p>landed {_num(rec.get('landed_from_home_m'))} m from home "
                     f"(height {_num(rec.get('final_height_m'))} m); items reached "
                     f"{rec.get('reached')} of {rec.get('items')}; flight wall time "
                     f"{_num(rec.get('flight_wall_s'), 1)} s.</p>")
    return "".join(parts)


def write_report(path: str | Path, *, airframe_name: str, airframe_path: str, sha256: str,
                 profile: str, records: Mapping[str, Mapping[str, Any]],
                 titles: Mapping[str, str], gate_failures: Sequence[str],
                 commands: Mapping[str, str]) -> Path:
    """Write ``report.html`` (atomically); ``commands`` maps a stage name to the command that
    re-runs it, and the campaign's failures carry their own ``fly_command``."""
    out = Path(path)
    verdict = "PASS" if not gate_failures else "FAIL"
    e = html.escape
    body = [f"<h1>vtolftc certify: {e(airframe_name)} — {verdict}</h1>",
            f"<p>airframe <code>{e(airframe_path)}</code>, sha256 <code>{e(sha256)}</code>, "
            f"profile <code>{e(profile)}</code></p>", "<h2>Verdict per stage</h2>"]
    rows = []
    for name, rec in records.items():
        v = str(rec.get("verdict", "?"))
        rows.append(f"<tr><td>{e(titles.get(name, name))}</td><td style='color:"
                    f"{_COLOURS.get(v, '#000')};font-weight:bold'>{e(v)}</td><td>"
                    f"{e('; '.join(rec.get('gate_failures', [])) or rec.get('error', ''))}"
                    f"</td><td>{_num(rec.get('wall_s'), 1)} s</td></tr>")
    body.append("<table><tr><th>stage</th><th>verdict</th><th>gate failures</th>"
                "<th>wall</th></tr>" + "".join(rows) + "</table>")
    body.append("<h2>Pictures</h2><div>")
    for fig in (survival_figure(records.get("campaign", {})),
                mu_figure(records.get("certificate", {})),
                track_figure(records.get("sitl", {}))):
        if fig:
            body.append(fig)
    body.append("</div>")
    for name, rec in records.items():
        body.append(f"<h2>{e(titles.get(name, name))}</h2>")
        body.append(_stage_section(name, rec))
        if rec.get("error"):
            body.append(f"<p>error: {e(str(rec['error']))}</p>")
        if rec.get("gate_failures") and name in commands:
            body.append(f"<p>re-run: <code>{e(commands[name])}</code></p>")
    fails = records.get("campaign", {}).get("failures", [])
    body.append(f"<h2>Every campaign failure ({len(fails)})</h2>")
    if fails:
        body.append(_table(("faults", "phase", "wind", "outcome", "recoverable", "re-fly"),
                           [(f["faults"], f["phase"], f["wind"], f["outcome"],
                             f.get("recoverable"), f["fly_command"]) for f in fails]))
    style = ("body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:"
             "collapse;margin:6px 0}td,th{border:1px solid #d0d7de;padding:2px 6px;"
             "font-size:13px}code{font-size:12px}img{max-width:100%;margin:4px}")
    doc = (f"<!doctype html><html><head><meta charset='utf-8'><title>certify "
           f"{e(airframe_name)}</title><style>{style}</style></head><body>"
           + "\n".join(body) + "</body></html>\n")
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(doc, encoding="utf-8")
    os.replace(tmp, out)
    return out
