"""Where table 4's squared error lies: case 1, GS-SHIF against SHIF, by time window.

    python docs/ds1-claims/case1_windows.py [--gains DIR]   # markdown; case1_errors.png

Flies the paper's case 1 (40 s, in-process, deterministic) with GS-SHIF and SHIF of one
gains folder (default: the shipped robust design) and prints, per time window after
t = 20 s, the mean airspeed and the RMS / largest |roll| and |pitch| error (attitude minus
its reference, degrees), plus the share of each controller's squared error that falls in
each window.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
WINDOWS = ((20.0, 22.0), (22.0, 24.0), (24.0, 26.0), (26.0, 30.0), (30.0, 34.0), (34.0, 40.0))


def fly(controller: str, gains: str | None, out: Path) -> dict[str, np.ndarray]:
    """Fly case 1 with ``controller``; the telemetry columns needed, as arrays."""
    cmd = [sys.executable, "-m", "vtolftc.cli", "fly", "--case", "1", "--controller",
           controller, "--duration", "40", "--no-plots", "--out", str(out)]
    if gains:
        cmd += ["--gains", gains]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, timeout=600)
    with open(out / "telemetry.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    col = {k: np.array([float(r[k]) for r in rows]) for k in
           ("time_s", "airspeed_m_s", "roll_deg", "roll_ref_deg", "pitch_deg", "pitch_ref_deg")}
    return {"t": col["time_s"], "V": col["airspeed_m_s"],
            "roll": col["roll_deg"] - col["roll_ref_deg"],
            "pitch": col["pitch_deg"] - col["pitch_ref_deg"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gains", default=None, help="gains folder (default: shipped)")
    ap.add_argument("--png", default=str(HERE / "case1_errors.png"))
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        runs = {c: fly(c, a.gains, Path(tmp) / c) for c in ("gs-shif", "shif")}
    print("| window [s] | airspeed [m/s] | GS-SHIF roll RMS / max [deg] | SHIF roll RMS / max | "
          "GS-SHIF pitch RMS / max | SHIF pitch RMS / max | share of GS-SHIF roll / pitch "
          "squared error |")
    print("|---|---|---|---|---|---|---|")
    g = runs["gs-shif"]
    tot = {ax: float(np.sum(g[ax][g["t"] >= 20.0] ** 2)) for ax in ("roll", "pitch")}
    for lo, hi in WINDOWS:
        cells = []
        for ax in ("roll", "pitch"):
            for c in ("gs-shif", "shif"):
                r = runs[c]
                m = (r["t"] >= lo) & (r["t"] < hi)
                e = r[ax][m]
                cells.append(f"{np.sqrt(np.mean(e ** 2)):.2f} / {np.max(np.abs(e)):.2f}")
        m = (g["t"] >= lo) & (g["t"] < hi)
        share = [100.0 * float(np.sum(g[ax][m] ** 2)) / max(tot[ax], 1e-12)
                 for ax in ("roll", "pitch")]
        print(f"| {lo:g}-{hi:g} | {float(np.mean(g['V'][m])):.1f} | " + " | ".join(cells)
              + f" | {share[0]:.0f} % / {share[1]:.0f} % |")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axs = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for ax, name in zip(axs, ("roll", "pitch"), strict=True):
        for c, style in (("gs-shif", "-"), ("shif", "--")):
            r = runs[c]
            m = r["t"] >= 20.0
            ax.plot(r["t"][m], r[name][m], style, label=c.upper())
        ax.set_ylabel(f"{name} error [deg]")
        ax.grid(True, alpha=0.3)
        ax.legend()
    axs[-1].set_xlabel("time [s] (fault at 22 s)")
    fig.suptitle("Case 1: attitude error after t = 20 s")
    fig.tight_layout()
    fig.savefig(a.png, dpi=100)
    plt.close(fig)
    return 0


if __name__ == "__main__":
    sys.exit(main())
