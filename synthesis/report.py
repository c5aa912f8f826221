"""Report of a synthesis run: markdown tables like the paper's tables 1-3 plus achieved norms,
gains and baselines, and PNG plots like figs. 3 (uncertainty weights) and 6 (closed-loop
poles) and the mu-versus-frequency curves. Degrees appear only here (none are needed: all
quantities are rates, gains and frequencies in SI units).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from vtolftc.synthesis.export import atomic_write_text
from vtolftc.synthesis.hinfnorm import frequency_response
from vtolftc.synthesis.loops import PARAM_NAMES, rate_controller
from vtolftc.synthesis.models import AXES, Axis, attitude_model
from vtolftc.synthesis.uncertainty import GAMMA_RANGE, relative_error

if TYPE_CHECKING:
    from vtolftc.synthesis.result import SynthesisResult

__all__ = ["PAPER_TABLE3", "crossovers", "write_report"]

# Paper table 3: (mu_Delta, mu_Delta-hat) per point, per axis (for comparison only).
PAPER_TABLE3: dict[str, tuple[tuple[float, float], ...]] = {
    "roll": ((0.996, 1.051), (0.872, 0.953), (0.758, 0.993), (0.731, 0.959), (0.690, 0.952),
             (0.639, 0.831)),
    "pitch": ((2.75, 2.748), (1.963, 1.964), (0.93, 0.987), (0.9767, 0.988), (0.6855, 0.974),
              (0.69, 0.984)),
    "yaw": ((3.57, 3.71), (0.306, 1.086), (0.898, 0.997), (0.134, 0.973), (0.523, 0.977),
            (0.859, 0.988)),
}


def _f(x: float, nd: int = 3) -> str:
    if not math.isfinite(x):
        return str(x)
    if x != 0 and (abs(x) < 10 ** -nd or abs(x) >= 1e5):
        return f"{x:.{nd - 1}e}"
    return f"{x:.{nd}f}"


def _g(x: float) -> str:
    return f"{x:.4g}"


def crossovers(af: Any, axis: Axis, airspeed_m_s: float, gains: dict[str, float],
               ) -> tuple[float, float]:
    """Rate-loop and plant-input loop crossover frequencies of one axis.

    The highest frequencies where |K_rate G_rate| and |L_u| = |K_rate (kp_angle G_angle +
    G_rate)| fall through 1.

    Parameters
    ----------
    af : Airframe
        The airframe.
    axis : {"roll", "pitch", "yaw"}
        The axis.
    airspeed_m_s : float
        Airspeed of the plant (m/s).
    gains : dict of str to float
        P-PID gains.

    Returns
    -------
    rate_crossover, input_crossover : float
        Frequencies (rad/s); nan if they never cross on 1e-3..1e4 rad/s.
    """
    G = attitude_model(af, axis, airspeed_m_s)
    w = np.logspace(-3, 4, 1400)
    F = frequency_response(G, w)
    gr, ga = F[:, 0, 0], F[:, 1, 0]
    K = frequency_response(rate_controller(gains["kp_rate"], gains["ki_rate"],
                                           gains["kd_rate"], gains["tf_rate_s"]), w)[:, 0, 0]
    out = []
    for L in (K * gr, K * (gains["kp_angle"] * ga + gr)):
        m = np.abs(L)
        idx = np.nonzero((m[:-1] >= 1.0) & (m[1:] < 1.0))[0]
        out.append(float(w[idx[-1]]) if idx.size else math.nan)
    return out[0], out[1]


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _layout(fig: Any) -> None:
    """Fixed margins (``tight_layout`` costs about 2 s per figure with log axes). The titles
    are placed with an explicit ``y=1.0`` for the same reason: matplotlib's automatic title
    position measures every tick label of every axes at each draw (about 1.3 s per figure
    of seven log-log panels)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=0.8 / w, right=1 - 0.25 / w, bottom=0.6 / h, top=1 - 0.6 / h,
                        wspace=0.25, hspace=0.3)


def _error_rows(a: Any, om: NDArray[np.float64], errors: NDArray[np.float64]) -> None:
    """About 24 of the relative-error curves, thin and grey, as one artist (a line per curve
    costs a Line2D each at every draw)."""
    from matplotlib.collections import LineCollection

    rows = errors[:: max(1, len(errors) // 24)]
    a.add_collection(LineCollection(
        [np.column_stack([om, np.maximum(r, 1e-6)]) for r in rows], colors="0.75",
        linewidths=0.6))
    a.set_xscale("log")
    a.set_yscale("log")


def _plots(res: SynthesisResult, out: Path, parts: tuple[str, ...] = ("design", "mu"),
           axes: tuple[Axis, ...] = AXES) -> list[str]:
    """The paper report's PNGs: ``design`` = weights and poles (known once the tunes are
    done), ``mu`` = the structured singular values."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names: list[str] = []
    af = res.airframe
    om = np.logspace(-3, 3, 241)
    # fig. 3: uncertainty weights over the relative errors, all points
    for ax in axes if "design" in parts else ():
        fig, axs = plt.subplots(2, 3, figsize=(13, 7), sharex=True)
        for k, d in enumerate(res.gs[ax]):
            a = axs.flat[k]
            w = d.weights[0]
            rel = relative_error(af, ax, w.point, om)
            _error_rows(a, om, rel.errors)
            a.loglog(om, rel.bound, "k--", lw=1, label="max relative error")
            a.loglog(om, w.Wt.magnitude(om), "r", lw=1.8, label="|W_t|")
            a.set_title(f"{ax} point {w.point.number} ({w.point.airspeed_m_s:g} m/s)", y=1.0)
            a.grid(True, alpha=0.3)
            a.set_ylim(1e-3, max(10.0, 2 * float(np.max(w.Wt.magnitude(om)))))
            if k == 0:
                a.legend(fontsize=8)
        for a in axs[1]:
            a.set_xlabel("frequency [rad/s]")
        fig.suptitle(f"Multiplicative uncertainty weight, {ax} (airspeed range, "
                     f"gamma in [{GAMMA_RANGE[0]}, {GAMMA_RANGE[1]}])")
        _layout(fig)
        name = f"wt_{ax}.png"
        fig.savefig(out / name, dpi=90)
        plt.close(fig)
        names.append(name)
    # fig. 6: closed-loop poles
    for ax in axes if "design" in parts else ():
        fig, a = plt.subplots(figsize=(7, 5))
        for d in res.gs[ax]:
            p = np.array(d.poles[0])
            a.plot(p.real, p.imag, "x", ms=8, mew=2,
                   label=f"point {d.weights[0].point.number} ({d.weights[0].point.airspeed_m_s:g}"
                         " m/s)")
        a.axvline(0.0, color="k", lw=0.8)
        a.set_xscale("symlog", linthresh=1.0)
        a.set_xlabel("real part [1/s] (symlog)")
        a.set_ylabel("imaginary part [rad/s]")
        a.set_title(f"Nominal closed-loop poles, {ax} (GS-SHIF)", y=1.0)
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
        _layout(fig)
        name = f"poles_{ax}.png"
        fig.savefig(out / name, dpi=90)
        plt.close(fig)
        names.append(name)
    # mu versus frequency
    for ax in axes if "mu" in parts else ():
        if ax not in res.mu_gs:
            continue
        fig, axs = plt.subplots(2, 3, figsize=(13, 7), sharex=True)
        for k, m in enumerate(res.mu_gs[ax]):
            a = axs.flat[k]
            a.semilogx(m.omegas, m.rs.upper, "b", label="mu_Delta (RS) upper")
            a.semilogx(m.omegas, m.rs.lower, "b:", label="mu_Delta lower")
            a.semilogx(m.omegas, m.rp.upper, "r", label="mu_Delta-hat (RP) upper")
            a.semilogx(m.omegas, m.rp.lower, "r:", label="mu_Delta-hat lower")
            a.axhline(1.0, color="k", lw=0.8)
            pt = res.points[k]
            a.set_title(f"{ax} point {pt.number} ({pt.airspeed_m_s:g} m/s)", y=1.0)
            a.grid(True, alpha=0.3)
            if k == 0:
                a.legend(fontsize=7)
        for a in axs[1]:
            a.set_xlabel("frequency [rad/s]")
        fig.suptitle(f"Structured singular values, {ax} (GS-SHIF)")
        _layout(fig)
        name = f"mu_{ax}.png"
        fig.savefig(out / name, dpi=90)
        plt.close(fig)
        names.append(name)
    return names


_PNG_KINDS = ("wt", "poles", "mu")


def png_order(names: list[str]) -> list[str]:
    """The report's PNG names in the report's order (kind: weights, poles, mu; then axis).

    Whichever order the per-axis jobs of :func:`design_plots` / :func:`mu_plots` finish.

    Parameters
    ----------
    names : list of str
        PNG file names.

    Returns
    -------
    list of str
        The names, sorted.
    """
    def key(n: str) -> tuple[int, int, str]:
        kind, _, rest = n.partition("_")
        ax = rest.removesuffix(".png")
        return (_PNG_KINDS.index(kind) if kind in _PNG_KINDS else len(_PNG_KINDS),
                AXES.index(ax) if ax in AXES else len(AXES), n)  # type: ignore[arg-type]
    return sorted(names, key=key)


def design_plots(res: SynthesisResult, out_dir: str | Path,
                 axes: tuple[Axis, ...] = AXES) -> list[str]:
    """The report's PNGs that do not need the mu analysis (uncertainty weights, poles).

    Picklable work: the pipeline draws them in the workers (one job per axis) while the mu
    analysis finishes and passes the names to :func:`write_report` (``design_pngs``).

    Parameters
    ----------
    res : SynthesisResult
        The synthesis result.
    out_dir : str or pathlib.Path
        Output folder.
    axes : tuple of str
        Axes to draw.

    Returns
    -------
    list of str
        Names of the PNGs written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if getattr(res, "method", "paper") == "robust":
        return _plots_robust(res, out, ("design",), axes)
    return _plots(res, out, ("design",), axes)


def mu_plots(res: SynthesisResult, out_dir: str | Path,
             axes: tuple[Axis, ...] = AXES) -> list[str]:
    """The report's mu figures of ``axes`` (those with a GS-SHIF mu analysis in ``res``).

    Parameters
    ----------
    res : SynthesisResult
        The synthesis result.
    out_dir : str or pathlib.Path
        Output folder.
    axes : tuple of str
        Axes to draw.

    Returns
    -------
    list of str
        Names of the PNGs written (``mu_pngs`` of :func:`write_report`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if getattr(res, "method", "paper") == "robust":
        return _plots_robust(res, out, ("mu",), axes)
    return _plots(res, out, ("mu",), axes)


def _pngs(res: SynthesisResult, out: Path, design_pngs: list[str] | None,
          mu_pngs: list[str] | None) -> list[str]:
    """The report's PNG names: those given, the others drawn here."""
    names = (design_plots(res, out) if design_pngs is None else list(design_pngs))
    names += mu_plots(res, out) if mu_pngs is None else list(mu_pngs)
    return png_order(names)


def write_report(res: SynthesisResult, out_dir: str | Path,
                 design_pngs: list[str] | None = None,
                 mu_pngs: list[str] | None = None) -> Path:
    """Write ``README.md`` and the PNGs into ``out_dir``.

    Parameters
    ----------
    res : SynthesisResult
        The synthesis result.
    out_dir : str or pathlib.Path
        Output folder.
    design_pngs, mu_pngs : list of str, optional
        The names :func:`design_plots` / :func:`mu_plots` returned for this ``res`` and
        ``out_dir`` (those figures are then not drawn again).

    Returns
    -------
    pathlib.Path
        The markdown file.
    """
    if getattr(res, "method", "paper") == "robust":
        return write_robust_report(res, out_dir, design_pngs, mu_pngs)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    af = res.airframe
    pngs = _pngs(res, out, design_pngs, mu_pngs)
    md: list[str] = [f"# Attitude synthesis report: {af.name}", ""]
    md += [f"Airframe file `{Path(af.source).name}`, sha256 `{af.sha256}`. Settings: "
           f"{res.settings.get('n_starts')} random starts + 1 classical start per tune, "
           f"seed {res.settings.get('seed')}.", ""]

    md += ["## Table 1: design points", ""]
    md.append(_table(["No.", "nominal V [m/s]", "perturbed range [m/s]", "gamma"],
                     [[str(p.number), _g(p.airspeed_m_s), f"[{_g(p.v_min_m_s)}, "
                       f"{_g(p.v_max_m_s)}]", f"[{GAMMA_RANGE[0]}, {GAMMA_RANGE[1]}]"]
                      for p in res.points]))

    md += ["", "## Table 2: weights", "",
           "Ws = (s/M + omega_b)/(s + A omega_b) with the paper's table 2 values (for DS-1; "
           "for another aircraft M is kept and omega_b scaled by the ratio of its authority "
           "bandwidth sqrt(u_max / (J r_max)) to DS-1's at the same point, "
           "`vtolftc.synthesis.design.table2_scaled`) and A = "
           f"{res.gs['roll'][0].weights[0].Ws.A:g}; Wr = ((r_max/u_max) s + omega_a 1e-3)/"
           f"(s + omega_a), r_max = {math.degrees(res.gs['roll'][0].weights[0].Wr.r_max_rad):g}"
           f" deg, omega_a = {res.gs['roll'][0].weights[0].Wr.omega_a_rad_s:g} rad/s (the "
           "paper's 5 rad/s times the actuator bandwidth over DS-1's), u_max = moment "
           "authority of the airframe about the axis "
           "at the nominal airspeed (lift rotors around their hover share + surfaces at full "
           "deflection; `vtolftc.synthesis.design.moment_authority`). W_t = gain prod (s/z + 1)/"
           "(s/p + 1), fitted over the relative errors (fig. 3 plots).", ""]
    rows = []
    for k, p in enumerate(res.points):
        row = [str(p.number), _g(p.airspeed_m_s)]
        for ax in AXES:
            w = res.gs[ax][k].weights[0]
            row += [_g(w.Ws.M), _g(w.Ws.omega_b_rad_s)]
        rows.append(row)
    md.append(_table(["No.", "V [m/s]"] + [f"{ax} {q}" for ax in AXES for q in
                                           ("M", "omega_b [rad/s]")], rows))
    md.append("")
    rows = []
    for k, p in enumerate(res.points):
        row = [str(p.number)]
        for ax in AXES:
            w = res.gs[ax][k].weights[0]
            mag = w.Wt.magnitude(np.logspace(-4, 4, 400))
            row += [_g(w.Wr.u_max_N_m), _g(float(w.Wt.magnitude(np.array([1e-6]))[0])),
                    _g(float(mag.max()))]
        rows.append(row)
    md.append(_table(["No."] + [f"{ax} {q}" for ax in AXES for q in
                                ("u_max [N m]", "|W_t(0)|", "max |W_t|")], rows))
    md += ["", "W_t per point (gain; zeros; poles [rad/s]):", ""]
    for ax in AXES:
        md.append(f"- {ax}: " + "; ".join(
            f"{d.weights[0].point.number}: {_g(d.weights[0].Wt.gain)}, z "
            f"{[round(z, 4) for z in d.weights[0].Wt.zeros_rad_s]}, p "
            f"{[round(z, 4) for z in d.weights[0].Wt.poles_rad_s]}" for d in res.gs[ax]))
    md += ["", "Remarks on the paper's table 2 for this airframe: pitch point 1 "
           "(omega_b = 0.012 rad/s) and yaw points 2-5 (omega_b = 0.002-0.007 rad/s) ask for "
           "almost no tracking bandwidth, and pitch point 3 allows a sensitivity peak "
           "M = 15.3. Where |W_t(0)| >= 1 (pitch 1-3, yaw 1-4 for DS-1) the stacked norm sits "
           "on that floor for every loop with integral action, so eq. 8 does not determine "
           "the gains there: the tie-break (smallest ||Ws S|| among the starts within 0.1 % "
           "of the best, `synthesis/design.py`) does. The values are kept as the paper gives "
           "them.", ""]

    md += ["## Achieved norms (GS-SHIF, eq. 8)", "",
           "gamma = ||[Ws S; Wt T_u; Wr R]||_inf; each requirement alone next to it. "
           "Crossovers: rate loop |K_rate G_rate| = 1 and plant-input loop |L_u| = 1 "
           "(highest crossing; '-' where the loop gain stays below 1: the airframe's own "
           "damping/stiffness dominates the rate loop there). The plant models (eq. 1-3) have "
           "no actuator lag: the DS-1 actuators (time constant 0.05 s) add about 45 deg of "
           "phase at 20 rad/s.", ""]
    rows = []
    for ax in AXES:
        for d in res.gs[ax]:
            p = d.weights[0].point
            wc_r, wc_u = crossovers(af, ax, p.airspeed_m_s, d.gains)
            rows.append([ax, str(p.number), _f(d.norms["gamma"]), _f(d.norms["Ws*S"]),
                         _f(d.norms["Wt*T"]), _f(d.norms["Wr*R"]),
                         "yes" if d.stable else "NO",
                         _f(wc_r, 2) if math.isfinite(wc_r) else "-",
                         _f(wc_u, 2) if math.isfinite(wc_u) else "-"])
    md.append(_table(["axis", "No.", "gamma", "||Ws S||", "||Wt T||", "||Wr R||",
                      "nominally stable", "rate-loop crossover [rad/s]",
                      "L_u crossover [rad/s]"], rows))
    md += ["", "## Final gains (GS-SHIF)", "",
           "kp_angle [1/s], kp_rate [N m s/rad], ki_rate [N m/rad], kd_rate [N m s^2/rad], "
           "tf_rate_s [s].", ""]
    rows = [[ax, str(d.weights[0].point.number), _g(d.weights[0].point.airspeed_m_s)]
            + [_g(d.gains[k]) for k in PARAM_NAMES] for ax in AXES for d in res.gs[ax]]
    md.append(_table(["axis", "No.", "V [m/s]", *PARAM_NAMES], rows))

    md += ["", "## Table 3: mu analysis (GS-SHIF)", "",
           "mu_Delta: robust stability, one complex scalar at the plant input (M = -W_t T_u); "
           "mu_Delta-hat: robust performance, blocks diag(Delta, Delta_P) with Delta_P on "
           "[Ws e; Wr u] (see `synthesis/robustness.py`). Values are the peak upper bounds "
           "over a 121-point grid 1e-3..1e3 rad/s; gap = largest upper - lower bound over the "
           "grid. Paper values for comparison (their airframe).", ""]
    rows = []
    for ax in AXES:
        if ax not in res.mu_gs:
            continue
        for k, m in enumerate(res.mu_gs[ax]):
            pp = PAPER_TABLE3[ax][k]
            rows.append([ax, str(res.points[k].number), _f(m.mu_rs), _f(m.gap_rs, 2),
                         _f(m.mu_rp), _f(m.gap_rp, 2), _g(pp[0]), _g(pp[1]),
                         "yes" if m.mu_rs < 1 else "no", "yes" if m.mu_rp < 1 else "no"])
    md.append(_table(["axis", "No.", "mu_Delta", "gap", "mu_Delta-hat", "gap",
                      "paper mu_Delta", "paper mu_Delta-hat", "RS", "RP"], rows))
    md += ["", _must_show(res), ""]

    md += ["## Baseline: SHIF (one constant P-PID per axis over all six points)", ""]
    rows = []
    for ax in AXES:
        d = res.shif[ax]
        rows.append([ax] + [_g(d.gains[k]) for k in PARAM_NAMES]
                    + [_f(d.norms["gamma"]), "yes" if d.stable else "NO"])
    md.append(_table(["axis", *PARAM_NAMES, "max gamma over points", "stable at all points"],
                     rows))
    md.append("")
    rows = []
    for ax in AXES:
        d = res.shif[ax]
        mus = res.mu_shif.get(ax)
        for k, n in enumerate(d.per_model_norms):
            r = [ax, str(res.points[k].number), _f(n["gamma"]), _f(n["Ws*S"]),
                 _f(n["Wt*T"]), _f(n["Wr*R"])]
            r += ([_f(mus[k].mu_rs), _f(mus[k].mu_rp)] if mus else ["-", "-"])
            rows.append(r)
    md.append(_table(["axis", "No.", "gamma", "||Ws S||", "||Wt T||", "||Wr R||", "mu_Delta",
                      "mu_Delta-hat"], rows))

    md += ["", "## Baseline: LQR (hover model, integral augmented)", ""]
    if res.lqr:
        from vtolftc.synthesis.baselines import LQR_Q, LQR_R

        md += [f"Q = diag{tuple(LQR_Q)}, R = {LQR_R}; law tau = k_int int(angle_ref - angle) "
               "+ k_angle (angle_ref - angle) - k_rate rate (see `synthesis/baselines.py`).",
               ""]
        md.append(_table(["axis", "k_int [N m/(rad s)]", "k_angle [N m/rad]",
                          "k_rate [N m s/rad]", "closed-loop poles (hover) [1/s]"],
                         [[ax, _g(q.k_int), _g(q.k_angle), _g(q.k_rate),
                           ", ".join(f"{z.real:.3g}{z.imag:+.3g}j" for z in q.poles)]
                          for ax, q in res.lqr.items()]))
    md += ["", "## Plots", ""] + [f"![{n}]({n})" for n in pngs]
    if res.times:
        md += ["", "## Run times", ""]
        md.append(_table(["stage", "wall time [s]"],
                         [[k, f"{v:.2f}"] for k, v in res.times.items()]))
    path = out / "README.md"
    atomic_write_text(path, "\n".join(md) + "\n")
    return path


def _must_show(res: SynthesisResult) -> str:
    """Plain statement of what holds and what does not (the issue's must-show)."""
    lines = ["**Must-show check.**"]
    unstable = [f"{ax} {d.label}" for ax in AXES for d in res.gs[ax] if not d.stable]
    lines.append("Nominal stability at all six points, three axes: "
                 + ("holds." if not unstable else f"FAILS at {', '.join(unstable)}."))
    if res.mu_gs:
        bad = []
        for ax in AXES:
            for k, m in enumerate(res.mu_gs.get(ax, [])):
                if res.points[k].number >= 3 and (m.mu_rs >= 1 or m.mu_rp >= 1):
                    bad.append(f"{ax} point {res.points[k].number} (mu_Delta {m.mu_rs:.3f}, "
                               f"mu_Delta-hat {m.mu_rp:.3f})")
        lines.append("mu_Delta and mu_Delta-hat < 1 at points 3-6 for all axes (the paper's "
                     "result): " + ("holds." if not bad else
                                    "does NOT hold for this airframe at " + "; ".join(bad)
                                    + "."))
        floors = []
        for ax in AXES:
            for d in res.gs[ax]:
                w0 = float(d.weights[0].Wt.magnitude(np.array([1e-6]))[0])
                if w0 >= 1.0:
                    floors.append(f"{ax} {d.weights[0].point.number} (|W_t(0)| = {w0:.2f})")
        if floors:
            lines.append("With integral action T_u(0) = 1, so mu_Delta >= |W_t(0)| for any "
                         "such controller; |W_t(0)| >= 1 (the perturbed set has steady-state "
                         "gains more than 100 % off the nominal, mostly from the airspeed "
                         "range, since gamma alone gives 60 %) at: " + ", ".join(floors)
                         + ". Robust stability cannot be certified there with these weights.")
    return "\n\n".join(lines)


# ------------------------------------------------------------------------------------------
# the robust method's report
# ------------------------------------------------------------------------------------------


def _grid(n: int) -> tuple[int, int]:
    return (2, (n + 1) // 2) if n > 3 else (1, n)


def _plots_robust(res: SynthesisResult, out: Path,
                  parts: tuple[str, ...] = ("design", "mu"),
                  axes: tuple[Axis, ...] = AXES) -> list[str]:
    """The robust report's PNGs: ``design`` = the weights, ``mu`` = the structured
    singular values."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names: list[str] = []
    af = res.airframe
    om = np.logspace(-3, 3, 241)
    n = len(res.points)
    rows, cols = _grid(n)
    for ax in axes if "design" in parts else ():
        fig, axs = plt.subplots(rows, cols, figsize=(3.3 * cols, 3.5 * rows), sharex=True)
        for k, d in enumerate(res.gs[ax]):
            a = axs.flat[k]
            w = d.weights[0]
            rel = relative_error(af, ax, w.point, om, nominal=w.nominal)
            _error_rows(a, om, rel.errors)
            a.loglog(om, rel.bound, "k--", lw=1, label="max relative error")
            a.loglog(om, w.Wt.magnitude(om), "r", lw=1.8, label="|W_t| (centred)")
            a.set_title(f"{ax} {w.point.number}: nominal {w.nominal[0]:.3g} m/s, "
                        f"gamma {w.nominal[1]:.2f}", fontsize=8, y=1.0)
            a.grid(True, alpha=0.3)
            a.set_ylim(1e-3, max(10.0, 2 * float(np.max(w.Wt.magnitude(om)))))
            if k == 0:
                a.legend(fontsize=7)
        for a in list(axs.flat)[n:]:
            a.set_visible(False)
        fig.suptitle(f"Multiplicative uncertainty weight about the centred nominal, {ax}")
        _layout(fig)
        name = f"wt_{ax}.png"
        fig.savefig(out / name, dpi=80)
        plt.close(fig)
        names.append(name)
    for ax in axes if "mu" in parts else ():
        if ax not in res.mu_gs:
            continue
        fig, axs = plt.subplots(rows, cols, figsize=(3.3 * cols, 3.5 * rows), sharex=True)
        for k, m in enumerate(res.mu_gs[ax]):
            a = axs.flat[k]
            a.semilogx(m.omegas, m.rs.upper, "b", label="mu_Delta (RS)")
            a.semilogx(m.omegas, m.rp.upper, "r", label="mu_Delta-hat (RP)")
            a.axhline(1.0, color="k", lw=0.8)
            pt = res.points[k]
            a.set_title(f"{ax} point {pt.number} ({pt.airspeed_m_s:g} m/s)", fontsize=8, y=1.0)
            a.grid(True, alpha=0.3)
            if k == 0:
                a.legend(fontsize=7)
        for a in list(axs.flat)[n:]:
            a.set_visible(False)
        fig.suptitle(f"Structured singular values, {ax} (robust GS-SHIF)")
        _layout(fig)
        name = f"mu_{ax}.png"
        fig.savefig(out / name, dpi=80)
        plt.close(fig)
        names.append(name)
    return names


def _active_bounds(d: Any, tol: float = 5e-3) -> list[str]:
    b = getattr(d, "bounds", None)
    if not b:
        return []
    out = []
    for k in PARAM_NAMES:
        lo, hi, v = b[k]["lower"], b[k]["upper"], d.gains[k]
        if v <= lo + tol * max(abs(lo), 1e-9) + 1e-12:
            out.append(f"{k} at lower {_g(lo)} ({b[k].get('lower_from', 'range')})")
        elif v >= hi * (1 - tol):
            out.append(f"{k} at upper {_g(hi)} ({b[k].get('upper_from', 'range')})")
    return out


def write_robust_report(res: SynthesisResult, out_dir: str | Path,
                        design_pngs: list[str] | None = None,
                        mu_pngs: list[str] | None = None) -> Path:
    """Report of the robust method (``synthesis/robust.py``).

    Points with their centred nominals, weights by rule beside table 2, rotor-out moments,
    norms, gains and active bounds, mu next to the disk and delay margins, SHIF and LQR.

    Parameters
    ----------
    res : SynthesisResult
        The synthesis result (``method == "robust"``).
    out_dir : str or pathlib.Path
        Output folder.
    design_pngs, mu_pngs : list of str, optional
        As in :func:`write_report`.

    Returns
    -------
    pathlib.Path
        The markdown file.
    """
    from vtolftc.synthesis.robust import (
        RobustSpec,
        disturbance_peak,
        high_frequency_gain_bound,
    )

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    af = res.airframe
    spec = RobustSpec()
    pngs = _pngs(res, out, design_pngs, mu_pngs)
    md: list[str] = [f"# Attitude synthesis report (robust method): {af.name}", ""]
    md += [f"Airframe file `{Path(af.source).name}`, sha256 `{af.sha256}`. Settings: "
           f"{res.settings.get('n_starts')} random starts + 1 classical start per tune, "
           f"seed {res.settings.get('seed')}. Method: `synthesis/robust.py` (its docstring "
           "states every rule). Declared requirements: worst single rotor-out angle "
           f"excursion {math.degrees(spec.excursion_rad):g} deg; stable with "
           f"{spec.delays.extra_margin_s * 1e3:g} ms extra loop delay; modelled loop delay "
           f"{spec.delays.transport_s * 1e3:g} ms (1.5 x {spec.delays.control_period_s * 1e3:g}"
           f" ms control period + {spec.delays.hil_transport_s * 1e3:g} ms HIL) folded into "
           "the actuator lag.", ""]
    md += ["## Design points and centred nominals", ""]
    rows = []
    for k, p in enumerate(res.points):
        row = [str(p.number), _g(p.airspeed_m_s), f"[{_g(p.v_min_m_s)}, {_g(p.v_max_m_s)}]"]
        for ax in AXES:
            w = res.gs[ax][k].weights[0]
            row.append(f"{_g(w.nominal[0])} / {w.nominal[1]:.2f}")
        rows.append(row)
    md.append(_table(["No.", "V [m/s]", "range [m/s]"] + [f"{ax} nominal V / gamma"
                                                           for ax in AXES], rows))
    md += ["", "## Weights: Ws by rule (table 2 beside), W_t about the centred nominal, "
           "rotor-out moments", "",
           "omega_b = min(omega_act/8, omega_u/2), omega_u = sqrt((u_max - d_max)/(J r_max)), "
           f"M = peak |S| of the 2nd-order loop with {spec.overshoot:.0%} overshoot. "
           "d_max = largest trim moment one lift rotor-out leaves (`rotor_out_moment`); "
           "u_max = rotors about their trim thrust + surfaces (`moment_authority_robust`); "
           "|W_t(0)| paper = the paper's cover (healthy nominal at the nominal airspeed).", ""]
    rows = []
    for ax in AXES:
        for k, p in enumerate(res.points):
            w = res.gs[ax][k].weights[0]
            r = w.rule or {}
            paper_w0 = "-"
            if p.number <= 6:
                from vtolftc.synthesis.uncertainty import cover as _cover

                paper_w0 = _g(_cover(af, ax, p)[0].gain)
            rows.append([ax, str(p.number), _g(w.Ws.M), _g(w.Ws.omega_b_rad_s),
                         str(r.get("limited_by", "")), _g(r.get("table2_M", math.nan)),
                         _g(r.get("table2_omega_b_rad_s", math.nan)), _g(w.Wr.u_max_N_m),
                         _g(w.d_max_N_m), paper_w0, _g(w.Wt.gain),
                         _g(float(np.max(w.Wt.magnitude(np.logspace(-3, 3, 241)))))])
    md.append(_table(["axis", "No.", "M", "omega_b [rad/s]", "omega_b limited by",
                      "table 2 M", "table 2 omega_b", "u_max [N m]", "d_max [N m]",
                      "|W_t(0)| paper", "|W_t(0)| centred", "max |W_t| centred"], rows))
    md += ["", "## Achieved norms, margins, mu (GS-SHIF)", "",
           "Norms unnormalised: gamma = eq. 8 stack about the centred nominal; Wd*Sd = the "
           "rotor-out objective (<= 1: the worst rotor-out excursion within "
           f"{math.degrees(spec.excursion_rad):g} deg / 1.25); Wdelay*T <= 1 guarantees "
           f"stability with {spec.delays.extra_margin_s * 1e3:g} ms extra delay (small gain). "
           "Delay margin (exact, on the design plant), disk margin alpha (balanced, "
           "guaranteed simultaneous gain / phase variation), linear peak angle after the "
           "rotor-out moment step.", ""]
    rows = []
    for ax in AXES:
        for k, d in enumerate(res.gs[ax]):
            n = d.norms
            w = d.weights[0]
            lm = res.margins_gs.get(ax, [None] * len(res.points))[k]
            mu = res.mu_gs.get(ax)
            pk = disturbance_peak(w.plant(af), d.gains, w.d_max_N_m)
            rows.append([ax, str(res.points[k].number), _f(n["gamma"]), _f(n["Ws*S"]),
                         _f(n["Wt*T"]), _f(n["Wr*R"]), _f(n.get("Wd*Sd", 0.0)),
                         _f(n["Wdelay*T"]), "yes" if d.stable else "NO",
                         "-" if lm is None else f"{lm.delay_margin_s * 1e3:.0f}",
                         "-" if lm is None else f"{lm.disk_alpha:.2f} (GM {lm.disk_gain_margin:.2f}"
                         f", PM {lm.disk_phase_margin_deg:.0f} deg)",
                         f"{math.degrees(pk):.1f}",
                         "-" if not mu else _f(mu[k].mu_rs), "-" if not mu else _f(mu[k].mu_rp)])
    md.append(_table(["axis", "No.", "gamma", "||Ws S||", "||Wt T||", "||Wr R||", "||Wd Sd||",
                      "||Wdelay T||", "stable", "delay margin [ms]", "disk margin",
                      "rotor-out peak [deg]", "mu_Delta", "mu_Delta-hat"], rows))
    lows = [f"{ax} {res.points[k].number} ({m.delay_margin_s * 1e3:.0f} ms)"
            for ax in AXES for k, m in enumerate(res.margins_gs.get(ax, []))
            if m.delay_margin_s < spec.delays.extra_margin_s]
    md += ["", "Delay-margin requirement (>= "
           f"{spec.delays.extra_margin_s * 1e3:g} ms at every point): "
           + ("holds." if not lows else "FAILS at " + ", ".join(lows) + "."), ""]
    md += ["## Final gains (GS-SHIF) and active bounds", "",
           "kp_angle [1/s], kp_rate [N m s/rad], ki_rate [N m/rad], kd_rate [N m s^2/rad], "
           "tf_rate_s [s]; K_hf = kp_rate + kd_rate/tf_rate_s against its gyro-noise bound.",
           ""]
    rows = []
    for ax in AXES:
        for k, d in enumerate(res.gs[ax]):
            g = d.gains
            khf = g["kp_rate"] + g["kd_rate"] / g["tf_rate_s"]
            hf = high_frequency_gain_bound(af, d.weights[0].Wr.u_max_N_m, spec)
            rows.append([ax, str(res.points[k].number), _g(res.points[k].airspeed_m_s)]
                        + [_g(g[p]) for p in PARAM_NAMES]
                        + [f"{_g(khf)} / {_g(hf['k_hf_max'])}",
                           "; ".join(_active_bounds(d)) or "none"])
    md.append(_table(["axis", "No.", "V [m/s]", *PARAM_NAMES, "K_hf / bound",
                      "active bounds"], rows))
    if res.shif:
        md += ["", "## SHIF (one constant P-PID per axis, same channels at every point)", ""]
        md.append(_table(["axis", *PARAM_NAMES, "max gamma", "max ||Wd Sd||",
                          "max ||Wdelay T||", "min delay margin [ms]", "stable at all points",
                          "active bounds"],
                         [[ax] + [_g(res.shif[ax].gains[p]) for p in PARAM_NAMES]
                          + [_f(res.shif[ax].norms["gamma"]),
                             _f(res.shif[ax].norms.get("Wd*Sd", 0.0)),
                             _f(res.shif[ax].norms["Wdelay*T"]),
                             f"{min(m.delay_margin_s for m in res.margins_shif[ax]) * 1e3:.0f}"
                             if ax in res.margins_shif else "-",
                             "yes" if res.shif[ax].stable else "NO",
                             "; ".join(_active_bounds(res.shif[ax])) or "none"]
                          for ax in AXES]))
        if res.mu_shif:
            md += ["", "SHIF mu per point (mu_Delta / mu_Delta-hat):", ""]
            md.append(_table(["axis"] + [str(p.number) for p in res.points],
                             [[ax] + [f"{m.mu_rs:.3f} / {m.mu_rp:.3f}"
                                      for m in res.mu_shif[ax]]
                              for ax in AXES if ax in res.mu_shif]))
    if res.lqr:
        from vtolftc.synthesis.baselines import LQR_Q, LQR_R

        md += ["", "## Baseline: LQR (the paper's: hover model, Bryson's rule, unchanged)", "",
               f"Q = diag{tuple(LQR_Q)}, R = {LQR_R}.", ""]
        md.append(_table(["axis", "k_int [N m/(rad s)]", "k_angle [N m/rad]",
                          "k_rate [N m s/rad]"],
                         [[ax, _g(q.k_int), _g(q.k_angle), _g(q.k_rate)]
                          for ax, q in res.lqr.items()]))
    md += ["", "## Plots", ""] + [f"![{n}]({n})" for n in pngs]
    if res.times:
        md += ["", "## Run times", ""]
        md.append(_table(["stage", "wall time [s]"],
                         [[k, f"{v:.2f}"] for k, v in res.times.items()]))
    path = out / "README.md"
    atomic_write_text(path, "\n".join(md) + "\n")
    return path
