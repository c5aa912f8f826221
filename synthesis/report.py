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
    """(rate-loop crossover, plant-input loop crossover) [rad/s]: the highest frequencies
    where |K_rate G_rate| and |L_u| = |K_rate (kp_angle G_angle + G_rate)| fall through 1
    (nan if they never cross on 1e-3..1e4 rad/s)."""
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
    """Fixed margins (``tight_layout`` costs about 2 s per figure with log axes)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=0.8 / w, right=1 - 0.25 / w, bottom=0.6 / h, top=1 - 0.6 / h,
                        wspace=0.25, hspace=0.3)


def _plots(res: SynthesisResult, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names: list[str] = []
    af = res.airframe
    om = np.logspace(-3, 3, 241)
    # fig. 3: uncertainty weights over the relative errors, all points
    for ax in AXES:
        fig, axs = plt.subplots(2, 3, figsize=(13, 7), sharex=True)
        for k, d in enumerate(res.gs[ax]):
            a = axs.flat[k]
            w = d.weights[0]
            rel = relative_error(af, ax, w.point, om)
            for row in rel.errors[:: max(1, len(rel.errors) // 24)]:
                a.loglog(om, np.maximum(row, 1e-6), color="0.75", lw=0.6)
            a.loglog(om, rel.bound, "k--", lw=1, label="max relative error")
            a.loglog(om, w.Wt.magnitude(om), "r", lw=1.8, label="|W_t|")
            a.set_title(f"{ax} point {w.point.number} ({w.point.airspeed_m_s:g} m/s)")
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
    for ax in AXES:
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
        a.set_title(f"Nominal closed-loop poles, {ax} (GS-SHIF)")
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
        _layout(fig)
        name = f"poles_{ax}.png"
        fig.savefig(out / name, dpi=90)
        plt.close(fig)
        names.append(name)
    # mu versus frequency
    for ax in AXES:
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
            a.set_title(f"{ax} point {pt.number} ({pt.airspeed_m_s:g} m/s)")
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


def write_report(res: SynthesisResult, out_dir: str | Path) -> Path:
    """Write ``README.md`` and the PNGs into ``out_dir``; returns the markdown path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    af = res.airframe
    pngs = _plots(res, out)
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
           "Ws = (s/M + omega_b)/(s + A omega_b) with the paper's table 2 values and A = "
           f"{res.gs['roll'][0].weights[0].Ws.A:g}; Wr = ((r_max/u_max) s + omega_a 1e-3)/"
           f"(s + omega_a), r_max = {math.degrees(res.gs['roll'][0].weights[0].Wr.r_max_rad):g}"
           " deg, omega_a = 5 rad/s, u_max = moment authority of the airframe about the axis "
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
