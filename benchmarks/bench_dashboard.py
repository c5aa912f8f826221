"""Cost of the run recording and of the web dashboard.

1. Rerun recorder: wall time per ``on_sample`` (microseconds, averaged over a 40 s run at
   250 Hz including the column flushes and ``on_finish``), with and without vehicle truth; and
   the in-process case-1 run (40 s) with and without the recorder (real-time factor).
2. SITL real-time factor of case 1 in lockstep over UDP: without dashboard, with the
   dashboard attached (its own ground-station link: the autopilot sends a second GCS stream),
   and with the dashboard open in a headless Chromium.
3. The dashboard's update rate: server side (updates/s pushed) and in the browser (status
   updates the page displayed per second, counted by a script in the page).

    python benchmarks/bench_dashboard.py [--skip-sitl] [--skip-browser] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import socket
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


SHOTS = Path(tempfile.gettempdir()) / "vtolftc_bench_dashboard"


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def bench_recorder(tmp: Path, repeats: int = 3) -> dict[str, Any]:
    from test_recording import _sample

    from vtolftc.telemetry.recording import RerunRecorder

    out: dict[str, Any] = {}
    for truth in (True, False):
        samples = [_sample(k, truth) for k in range(10_000)]     # 40 s at 250 Hz
        per = []
        for r in range(repeats):
            rec = RerunRecorder(tmp / f"bench_{truth}_{r}.rrd")
            rec.on_start({})
            t0 = time.perf_counter()
            for s in samples:
                rec.on_sample(s)
            rec.on_finish({})
            per.append((time.perf_counter() - t0) / len(samples) * 1e6)
        out[f"us_per_sample_{'truth' if truth else 'no_truth'}"] = statistics.median(per)
    out["file_bytes_40s"] = (tmp / "bench_True_0.rrd").stat().st_size
    return out


def bench_case_run(tmp: Path) -> dict[str, Any]:
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.runners.scenario import paper_scenario, run_scenario
    from vtolftc.telemetry.recording import RerunRecorder

    af = load_airframe()
    scen = paper_scenario(1, 40.0, airframe=af)
    run_scenario(paper_scenario(1, 1.0, airframe=af), airframe=af)       # warm up (JIT)
    res0 = run_scenario(scen, airframe=af, observers=[_Null()])
    res1 = run_scenario(scen, airframe=af, observers=[RerunRecorder(tmp / "case1.rrd")])
    n = 40.0 * 250
    return {
        # the runner builds VehicleTruth only when there are observers: the baseline has a
        # do-nothing observer, so the difference is the recorder's own cost
        "rtf_null_observer": res0.real_time_factor,
        "rtf_with_recorder": res1.real_time_factor,
        "observer_us_per_step_null": res0.timing_s["observers"] / n * 1e6,
        "observer_us_per_step_recorder": res1.timing_s["observers"] / n * 1e6,
        "rrd_bytes": (tmp / "case1.rrd").stat().st_size,
    }


class _Null:
    def on_start(self, info: Any) -> None: ...
    def on_sample(self, sample: Any) -> None: ...
    def on_event(self, t: int, kind: str, text: str) -> None: ...
    def on_finish(self, metrics: Any) -> None: ...


def _sitl_once(tmp: Path, name: str, dashboard: bool, browser: bool) -> dict[str, Any]:
    from vtolftc.airframe.loader import load_airframe
    from vtolftc.runners.scenario import paper_scenario
    from vtolftc.runners.sitl import SitlConfig, SitlRun

    af = load_airframe()
    extra: list[str] = []
    udp = _free_port(socket.SOCK_DGRAM)
    if dashboard:
        extra = ["--gcs-link", f"udp-client://127.0.0.1:{udp}"]
    cfg = SitlConfig(case="1", out_dir=tmp / name, extra_autopilot_args=extra)
    out: dict[str, Any] = {}
    dash = page = None
    with SitlRun(cfg) as run:
        try:
            if dashboard:
                from vtolftc.dashboard.web import Dashboard

                dash = Dashboard(f"udp-server://127.0.0.1:{udp}",
                                 port=_free_port(socket.SOCK_STREAM), rate_hz=10.0, airframe=af)
            run.start()
            if browser and dash is not None:
                from support.browser import DashboardPage

                page = DashboardPage(dash.page_url)
                page.wait(lambda s: s["link"] == "ok", 30, "the link")
                page.start_update_counter()
            u0, t0 = (dash.updates if dash else 0), time.monotonic()
            res = run.fly(paper_scenario(1, 40.0, airframe=af))
            wall = time.monotonic() - t0
            out["rtf"] = res.real_time_factor
            out["flight_wall_s"] = res.flight_wall_s
            if dash is not None:
                out["dashboard_updates_per_s"] = (dash.updates - u0) / wall
            if page is not None:
                n, dt = page.update_rate()
                out["browser_updates_per_s"] = n / dt if dt > 0 else 0.0
                shot = page.screenshot(SHOTS / f"{name}.png")
                out["screenshot"] = str(shot)
        finally:
            if page is not None:
                page.close()
            if dash is not None:
                dash.close()
    return out


def bench_browser_fake(tmp: Path, seconds: float = 10.0) -> dict[str, Any]:
    """Update rate in the browser with a light (kinematic) autopilot: the page's own limit."""
    from support.browser import DashboardPage
    from support.fake_autopilot import FakeAutopilot

    from vtolftc.dashboard.web import Dashboard

    udp = _free_port(socket.SOCK_DGRAM)
    out: dict[str, Any] = {}
    for rate in (10.0, 20.0):
        with Dashboard(f"udp-server://127.0.0.1:{udp}", port=_free_port(socket.SOCK_STREAM),
                       rate_hz=rate) as dash, \
                FakeAutopilot(f"udp-client://127.0.0.1:{udp}", speed=2.0), \
                DashboardPage(dash.page_url) as page:
            page.wait(lambda s: s["link"] == "ok", 30, "the link")
            u0, t0 = dash.updates, time.monotonic()
            page.start_update_counter()
            time.sleep(seconds)
            n, dt = page.update_rate()
            out[f"rate_{rate:g}"] = {"server_updates_per_s": (dash.updates - u0)
                                     / (time.monotonic() - t0),
                                     "browser_updates_per_s": n / dt}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--skip-sitl", action="store_true")
    ap.add_argument("--skip-browser", action="store_true")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    from support.browser import find_chromedriver, find_chromium

    browser = not args.skip_browser and find_chromium() and find_chromedriver()
    results: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="bench_dashboard_") as d:
        tmp = Path(d)
        results["recorder"] = bench_recorder(tmp)
        print("recorder:", json.dumps(results["recorder"], indent=1), flush=True)
        results["case_run"] = bench_case_run(tmp)
        print("in-process case 1:", json.dumps(results["case_run"], indent=1), flush=True)
        if browser:
            results["browser_fake_autopilot"] = bench_browser_fake(tmp)
            print("browser (kinematic autopilot):",
                  json.dumps(results["browser_fake_autopilot"], indent=1), flush=True)
        if not args.skip_sitl:
            runs = [("sitl_plain", False, False), ("sitl_dashboard", True, False)]
            if browser:
                runs.append(("sitl_dashboard_browser", True, True))
            for name, dash, br in runs:
                results[name] = _sitl_once(tmp, name, dash, br)
                print(f"{name}:", json.dumps(results[name], indent=1), flush=True)
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
