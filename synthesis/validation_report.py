"""The validation section of the synthesis report: gain plots and the checks between points.

Writes, into a report folder, SVG figures (matplotlib, no other dependency) and a markdown
page ``validation.md`` that shows them:

- ``validation-gains-<axis>.svg``: every gain of the axis against airspeed, the schedule as
  the autopilot flies it (piecewise linear between the breakpoints, held beyond them), the
  breakpoints and the design points marked, and the gain surface as a smooth curve when the
  document carries one (``synthesis_method`` ``"surface"``, its Legendre coefficients);
- ``validation-checks.svg``: per axis against airspeed on the 4x grid, the largest real part
  of the closed-loop poles, the gain, phase and delay margins, and mu (lumped mu_RS, the
  mixed-mu upper bound with frozen gains and the cell bound), requirement lines drawn and
  failing grid points circled.

Degrees appear only here (phase margins).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from vtolftc.synthesis.export import atomic_write_text
from vtolftc.synthesis.loops import PARAM_NAMES
from vtolftc.synthesis.models import AXES
from vtolftc.synthesis.validation import FlownSchedule, ValidationResult, design_grid

__all__ = ["gain_plots", "surface_curves", "validation_plots", "write_validation_report"]

_UNITS = {"kp_angle": "1/s", "kp_rate": "N m s/rad", "ki_rate": "N m/rad",
          "kd_rate": "N m s^2/rad", "tf_rate_s": "s"}


def surface_curves(doc: Mapping[str, Any], axis: str, airspeeds_m_s: Any,
                   ) -> dict[str, np.ndarray] | None:
    """The gain surface of ``axis`` recorded in a schedule document, at ``airspeeds_m_s``.

    Parameters
    ----------
    doc : mapping
        A gain-schedule document written by
        :func:`vtolftc.synthesis.surfaces.schedule_from_surfaces` (``surfaces`` metadata).
    axis : str
        The axis.
    airspeeds_m_s : array_like of float
        Airspeeds [m/s].

    Returns
    -------
    dict of str to ndarray, or None
        Gain name -> values (unclipped: the smooth surface; the file holds it clipped at
        the breakpoints); None when the document has no surface.
    """
    sf = (doc.get("surfaces") or {}).get(axis)
    if not sf or sf.get("basis") != "legendre":
        return None
    from vtolftc.synthesis.surfaces import SurfaceBasis

    b = SurfaceBasis(int(sf["degree"]), float(sf["v_lo_m_s"]), float(sf["v_hi_m_s"]))
    Phi = b.evaluate(airspeeds_m_s)
    return {k: Phi @ np.asarray(sf["coefficients"][k], float) for k in PARAM_NAMES}


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def gain_plots(doc: Mapping[str, Any], out_dir: str | Path) -> list[Path]:
    """One SVG per axis: every gain against airspeed (see the module docstring).

    Parameters
    ----------
    doc : mapping
        The gain-schedule document.
    out_dir : str or pathlib.Path
        The folder (created if missing).

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    plt = _plt()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sched = FlownSchedule(doc)
    bps = np.asarray(sched.breakpoints_m_s)
    dps = [p.airspeed_m_s for p in design_grid(doc)]
    span = max(bps[-1] - bps[0], 1.0)
    v = np.linspace(bps[0] - 0.05 * span, bps[-1] + 0.05 * span, 400)
    files = []
    for ax in AXES:
        fig, axs = plt.subplots(1, len(PARAM_NAMES), figsize=(16, 3.2))
        surf = surface_curves(doc, ax, v)
        for k, a in zip(PARAM_NAMES, axs, strict=True):
            flown = [sched.gains_at(ax, float(x))[k] for x in v]
            a.plot(v, flown, "C0-", lw=1.5, label="as flown (interpolated)")
            a.plot(bps, [sched.gains_at(ax, float(x))[k] for x in bps], "C0.", ms=6,
                   label="breakpoints")
            dv = [x for x in dps if bps[0] <= x <= bps[-1]]
            a.plot(dv, [sched.gains_at(ax, float(x))[k] for x in dv], "ks", mfc="none",
                   ms=8, label="design points")
            if surf is not None:
                a.plot(v, surf[k], "C1--", lw=1.0, label="surface (unclipped)")
            a.set_title(f"{ax} {k}", fontsize=9)
            a.set_xlabel("airspeed (m/s)", fontsize=8)
            a.set_ylabel(_UNITS[k], fontsize=8)
            a.tick_params(labelsize=7)
            a.grid(alpha=0.3)
        axs[0].legend(fontsize=6, loc="best")
        fig.tight_layout()
        p = out / f"validation-gains-{ax}.svg"
        fig.savefig(p, format="svg")
        plt.close(fig)
        files.append(p)
    return files


def _col(rows: list[Any], f: Any) -> np.ndarray:
    return np.array([np.nan if (x := f(r)) is None or not math.isfinite(x) else x
                     for r in rows], float)


def validation_plots(res: ValidationResult, out_dir: str | Path) -> Path:
    """``validation-checks.svg``: poles, margins and mu against airspeed, per axis.

    Parameters
    ----------
    res : ValidationResult
        The validation.
    out_dir : str or pathlib.Path
        The folder (created if missing).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    plt = _plt()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    req = res.requirements
    axes = [ax for ax in AXES if any(r.axis == ax for r in res.rows)]
    fig, grid = plt.subplots(len(axes), 5, figsize=(17, 3.0 * len(axes)), squeeze=False)
    for ax, row in zip(axes, grid, strict=True):
        rows = sorted((r for r in res.rows if r.axis == ax), key=lambda r: r.airspeed_m_s)
        V = np.array([r.airspeed_m_s for r in rows])
        bad = np.array([bool(r.failures) for r in rows])
        m = [r.margins for r in rows]
        panels = [
            ("max Re(pole) (rad/s)", [(_col(rows, lambda r: r.max_real_pole_rad_s), "C0",
                                       "nominal")], 0.0),
            ("gain margin (dB)", [(_col(m, lambda x: x and x.gain_margin_upper_db), "C0",
                                   "upper"),
                                  (_col(m, lambda x: x and x.gain_margin_lower_db), "C2",
                                   "lower")], req.gain_margin_db),
            ("|phase margin| (deg)", [(_col(m, lambda x: x and abs(x.phase_margin_deg)),
                                       "C0", "PM")], req.phase_margin_deg),
            ("delay margin (ms)", [(1e3 * _col(m, lambda x: x and x.delay_margin_s), "C0",
                                    "DM")], 1e3 * req.delay_margin_s),
            ("mu", [(_col(rows, lambda r: r.mu_rs), "C0", "mu_RS (lumped)"),
                    (_col(rows, lambda r: r.mixed_mu_upper), "C1", "mixed mu, frozen"),
                    (_col(rows, lambda r: r.mixed_mu_cell), "C3", "mixed mu, cell")],
             req.mu),
        ]
        for a, (title, series, limit) in zip(row, panels, strict=True):
            for y, c, lab in series:
                a.plot(V, y, ".-", color=c, lw=1, ms=4, label=lab)
                if bad.any():
                    a.plot(V[bad], y[bad], "o", mfc="none", mec="r", ms=9)
            a.axhline(limit, color="r", lw=0.8, ls=":")
            if title.startswith("gain"):
                a.axhline(-limit, color="r", lw=0.8, ls=":")
            for dv in res.design_airspeeds_m_s:
                a.axvline(dv, color="k", lw=0.4, alpha=0.3)
            a.set_title(f"{ax}: {title}", fontsize=9)
            a.set_xlabel("airspeed (m/s)", fontsize=8)
            a.tick_params(labelsize=7)
            a.grid(alpha=0.3)
            if len(series) > 1:
                a.legend(fontsize=6)
    fig.tight_layout()
    p = out / "validation-checks.svg"
    fig.savefig(p, format="svg")
    plt.close(fig)
    return p


def _f(x: Any, nd: int = 3) -> str:
    if x is None:
        return "-"
    if not math.isfinite(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.{nd}f}"


def write_validation_report(doc: Mapping[str, Any], res: ValidationResult,
                            out_dir: str | Path) -> Path:
    """``validation.md`` with the gain plots, the checks figure, the summary and the table.

    Parameters
    ----------
    doc : mapping
        The validated gain-schedule document.
    res : ValidationResult
        Its validation.
    out_dir : str or pathlib.Path
        The report folder.

    Returns
    -------
    pathlib.Path
        The markdown file.
    """
    out = Path(out_dir)
    gains = gain_plots(doc, out)
    checks = validation_plots(res, out)
    req = res.requirements
    md = [f"# Validation between design points: {res.controller}", "",
          f"Grid {res.density}x the design grid ({len(res.grid_m_s)} airspeeds over "
          f"{res.grid_m_s[0]:g}-{res.grid_m_s[-1]:g} m/s; design points "
          + ", ".join(f"{v:g}" for v in res.design_airspeeds_m_s) + " m/s), gains as the "
          "autopilot interpolates them, the plant at each airspeed (`synthesis/validation.py` "
          "states every choice). Requirements: upper gain margin >= "
          f"{req.gain_margin_db:g} dB (lower <= -{req.gain_margin_db:g} dB), |phase margin| "
          f">= {req.phase_margin_deg:g} deg, delay margin >= {req.delay_margin_s * 1e3:g} ms, "
          f"mu_RS and the mixed-mu cell bound < {req.mu:g}. Continuity over the airspeed "
          "range: the plant's airspeed is a real parameter in each grid cell (exact LFT, "
          "proved); the gains' change across a cell is covered by a finite-difference "
          "Lipschitz estimate (not proved).", "", "## Gains against airspeed", ""]
    md += [f"![{p.stem}]({p.name})" for p in gains]
    md += ["", "## Checks on the grid", "", f"![checks]({checks.name})", "",
           "| axis | max Re(pole) (rad/s) | min GM (dB) | min PM (deg) | min DM (ms) | "
           "max mu_RS | max mixed mu (frozen) | max mixed mu (cell) | failures | "
           "between points |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for ax, s in res.summary().items():
        dm, gm = s["min_delay_margin_s"], s["min_gain_margin_db"]
        md.append(f"| {ax} | {_f(s['max_real_pole_rad_s'])} | "
                  f"{'inf' if gm is None else _f(gm, 2)} | "
                  f"{_f(s['min_phase_margin_deg'], 1)} | "
                  f"{_f(None if dm is None else 1e3 * dm, 1)} | {_f(s['max_mu_rs'])} | "
                  f"{_f(s['max_mixed_mu_upper'])} | {_f(s['max_mixed_mu_cell'])} | "
                  f"{s['failures']} | {s['failures_between']} |")
    md += ["", "## Failures", ""]
    fails = res.failures
    if not fails:
        md.append("None.")
    for r in fails:
        where = "design point" if r.design_point else "between points"
        md.append(f"- {r.axis} {r.airspeed_m_s:g} m/s ({where}): " + "; ".join(r.failures))
    md += ["", "## Every grid point", "",
           "| axis | V (m/s) | design | max Re(pole) | GM up (dB) | GM low (dB) | PM (deg) | "
           "DM (ms) | mu_RS | mixed mu frozen | ends | cell |",
           "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|---:|"]
    for r in res.rows:
        m = r.margins
        ends = ("-" if r.mixed_mu_ends is None
                else " / ".join(_f(e) for e in r.mixed_mu_ends))
        md.append(
            f"| {r.axis} | {r.airspeed_m_s:g} | {'yes' if r.design_point else ''} | "
            f"{_f(r.max_real_pole_rad_s)} | {_f(m and m.gain_margin_upper_db, 2)} | "
            f"{_f(m and m.gain_margin_lower_db, 2)} | "
            f"{_f(m and m.phase_margin_deg, 1)} | "
            f"{_f(m and 1e3 * m.delay_margin_s, 1)} | {_f(r.mu_rs)} | "
            f"{_f(r.mixed_mu_upper)} | {ends} | {_f(r.mixed_mu_cell)} |")
    path = out / "validation.md"
    atomic_write_text(path, "\n".join(md) + "\n")
    return path
