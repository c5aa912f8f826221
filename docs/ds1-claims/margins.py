"""Delay and disk margins of a shipped gain schedule at its design points, on the robust
method's design plant (eq. 1-3 + actuator lag + 8 ms modelled loop delay, healthy, nominal
airspeed), so both designs are judged on the same loop.

    python docs/ds1-claims/margins.py firmware_sim/autopilot/gains/paper/gs-shif.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from vtolftc.airframe.loader import load_airframe
from vtolftc.synthesis.robust import design_plant, loop_margins


def main(path: str) -> int:
    af = load_airframe()
    doc = json.loads(Path(path).read_text())
    bp = doc["airspeed_breakpoints_m_s"]
    print("| axis | V [m/s] | delay margin [ms] | disk alpha | crossover [rad/s] |")
    print("|---|---:|---:|---:|---:|")
    for ax in ("roll", "pitch", "yaw"):
        t = doc["axes"][ax]
        for i, V in enumerate(bp):
            g = {k: t[k][i] for k in ("kp_angle", "kp_rate", "ki_rate", "kd_rate", "tf_rate_s")}
            m = loop_margins(design_plant(af, ax, V, 0.0), g)
            print(f"| {ax} | {V:g} | {m.delay_margin_s * 1e3:.0f} | {m.disk_alpha:.2f} | "
                  f"{m.crossover_rad_s:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
