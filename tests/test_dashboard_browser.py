"""The dashboard in a real headless Chromium against a running SITL (vehicle and autopilot
processes over UDP, real time): arm, take off, press "Transition to fixed-wing" and see the
VTOL state change and the aircraft move; the screenshot goes to the test's output folder.

Skipped only when no chromium is installed (CI installs Debian's chromium and
chromium-driver); a missing chromedriver is a failure that says what to install.
"""

from __future__ import annotations

import os
import shutil
import socket
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from support.browser import find_chromedriver, find_chromium

pytestmark = pytest.mark.slow


def _free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def chromium():
    if find_chromium() is None:
        msg = "chromium not installed (apt-get install -y chromium chromium-driver)"
        if os.environ.get("VTOLFTC_REQUIRE_BROWSER") == "1":   # set by .ci/run: never skip
            pytest.fail(msg)
        pytest.skip(msg)
    if find_chromedriver() is None:
        pytest.fail("chromium is installed but chromedriver is not: "
                    "apt-get install -y chromium-driver")


@pytest.fixture
def sitl(tmp_path, ds1):
    """Vehicle + autopilot processes in real time, a ground station, and the dashboard."""
    from vtolftc.dashboard.web import Dashboard
    from vtolftc.runners.sitl import SitlConfig, SitlRun

    # duration: far beyond what the test needs (it closes the run); under load every wait
    # below may take its full time and the SITL must not end first
    # COM_DISARM_PRFLT -1 (PX4: no pre-flight auto-disarm): under load a press of "Takeoff"
    # may come more than the default 10 s after "Arm" was accepted
    # COM_HIL_LOSS_T 2 s and the vehicle's --output-timeout 2 s (both 0.5 s by default): a
    # loaded machine does not schedule a real-time process for up to ~1 s (session 13's stall
    # probe); session 14, the file run at load 10-11 without burners: a 0.5 s HIL gap at
    # t = 34.7 s in the climb, failsafe landing and disarm, the test timed out waiting for 30 m
    # while the page itself answered. The real-time failsafes have their own tests
    # (test_failsafe.py, test_sitl_resilience.py); this one is about the page
    run = SitlRun(SitlConfig(realtime=True, out_dir=tmp_path / "sitl", duration_s=900.0,
                             startup_timeout_s=60.0,
                             extra_autopilot_args=["--param", "COM_DISARM_PRFLT=-1",
                                                   "--param", "COM_HIL_LOSS_T=2"],
                             extra_vehicle_args=["--output-timeout", "2"]))
    dash = None
    try:
        run.start()
        dash = Dashboard(run.gs.url, ground_station=run.gs, port=_free_tcp_port(),
                         rate_hz=10.0, airframe=ds1)
        yield run, dash
    finally:
        if dash is not None:
            dash.close()
        run.close()           # SIGTERM, then SIGKILL after a grace period, by pid


def _scene_change(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels of the 3-D view (left of the control panel) that changed."""
    w = a.shape[1] - 450
    d = np.abs(a[:, :w].astype(int) - b[:, :w].astype(int)).sum(axis=2)
    return float(np.mean(d > 30))


# -- what a screenshot of the dashboard must show -------------------------------------------
_PANEL_LEFT_JS = ("const e = document.getElementById('vtolftc-status');"
                  "return e ? e.getBoundingClientRect().left : null;")
# Where the command buttons sit below the top of the status panel (px): the same before the
# first command and after the transition, whatever texts the panel shows meanwhile.
_BUTTONS_BELOW_STATUS_JS = (
    "const s = document.getElementById('vtolftc-status'); if (!s) return null;"
    "const top = s.getBoundingClientRect().top;"
    "return Array.from(document.querySelectorAll('button'))"
    ".filter(b => ['Arm', 'Takeoff', 'Transition to fixed-wing'].includes(b.innerText.trim()))"
    ".map(b => b.getBoundingClientRect().top - top);")
_TOAST_W = 330     # the "software WebGL" notice at the top left of the view (not the scene)


def _rotor_pixels(img: np.ndarray) -> np.ndarray:
    """Mask of the rotor discs' colour (orange, lit, over the sky); not the path's yellow
    (blue channel near 0), not the grey grid, not the blue sky."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r >= 190) & (g >= 140) & (g <= 210) & (b >= 80) & (b <= 170) & (r - b >= 50)


def view_problems(img: np.ndarray, panel_left: float) -> list[str]:
    """What is wrong with a screenshot of the dashboard (empty list: nothing).

    - the 3-D view, in six horizontal bands (right of the notice, left of the control panel):
      no band may be mostly blank white (an unrendered canvas; the empty band above the
      horizon before the sky);
    - the aircraft inside the frame: at least 40 pixels of rotor colour, centred in the
      middle half of the view (the camera looks at the aircraft);
    - the control panel not blank (its pixels vary).
    """
    h, w, _ = img.shape
    x1 = int(panel_left) - 10
    out: list[str] = []
    view = img[:, _TOAST_W:x1].astype(int)
    for k in range(6):
        band = view[k * h // 6:(k + 1) * h // 6]
        white = float(np.mean(np.all(band > 240, axis=2)))
        if white > 0.5:
            out.append(f"band {k} of the 3-D view is {100 * white:.0f} % blank white")
    m = _rotor_pixels(img[:, :x1])
    n = int(m.sum())
    if n < 40:
        out.append(f"aircraft not in the frame ({n} rotor pixels)")
    else:
        ys, xs = np.nonzero(m)
        cy, cx = float(ys.mean()), float(xs.mean())
        if not (0.25 * w < cx < 0.75 * w and 0.25 * h < cy < 0.75 * h):
            out.append(f"aircraft off centre at ({cx:.0f}, {cy:.0f}) px in {w}x{h}")
    panel = img[:, x1 + 20:].astype(float)
    if panel.size == 0 or float(panel.std()) < 10.0:
        out.append("control panel blank")
    return out


def test_view_problems_tells_good_from_bad_screenshots():
    """The screenshot checks against synthetic screenshots (no browser)."""
    from vtolftc.dashboard.web import sky_gradient

    h, w, panel = 577, 1100, 700
    sky = np.asarray(Image.fromarray(sky_gradient()).resize((w, h))).copy()
    sky[:, panel:] = 255
    sky[40:60, panel + 30:] = (20, 150, 60)                # the panel's status line
    good = sky.copy()
    good[270:300, 530:570] = (225, 185, 130)               # rotor discs in the middle
    assert view_problems(good, panel) == []
    blank = np.full_like(good, 255)
    blank[40:60, panel + 30:] = (20, 150, 60)
    probs = view_problems(blank, panel)
    assert any("band 0" in p for p in probs) and any("not in the frame" in p for p in probs)
    off = sky.copy()
    off[10:40, 600:640] = (225, 185, 130)                  # aircraft at the top edge
    assert any("off centre" in p for p in view_problems(off, panel))
    band = good.copy()
    band[: h // 6, :panel] = 255                          # white above the horizon
    assert view_problems(band, panel) == ["band 0 of the 3-D view is 100 % blank white"]
    nopanel = good.copy()
    nopanel[:, panel:] = 250
    assert view_problems(nopanel, panel) == ["control panel blank"]


@pytest.fixture
def far_flight(ds1):
    """The dashboard watching the kinematic stand-in autopilot (fast, no SITL)."""
    from support.fake_autopilot import FakeAutopilot

    from vtolftc.dashboard.web import Dashboard

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        udp = int(s.getsockname()[1])
    dash = Dashboard(f"udp-server://127.0.0.1:{udp}", port=_free_tcp_port(), rate_hz=10.0,
                     airframe=ds1)
    ap = None
    try:
        ap = FakeAutopilot(f"udp-client://127.0.0.1:{udp}", speed=4.0)
        yield dash, ap
    finally:
        if ap is not None:
            ap.close()
        dash.close()


_WEBGL_RED_JS = """
const c = document.createElement('canvas'); c.width = 8; c.height = 8;
const gl = c.getContext('webgl2');
if (!gl) return null;
const info = gl.getExtension('WEBGL_debug_renderer_info');
gl.clearColor(1.0, 0.0, 0.0, 1.0); gl.clear(gl.COLOR_BUFFER_BIT);
const px = new Uint8Array(4); gl.readPixels(4, 4, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
return [info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : '', Array.from(px)];
"""


def test_the_browser_draws_webgl_on_swiftshader_without_a_gpu_process(chromium):
    """How the instrument is started (tests/support/browser.py): WebGL still works, on
    SwiftShader, but the GPU service is a thread of the browser process - no separately
    scheduled GPU process for the renderer to wait on under load."""
    from support.browser import DashboardPage

    with DashboardPage("data:text/html,<title>webgl</title>", width=400, height=300) as page:
        renderer, px = page._call(lambda: page.driver.execute_script(_WEBGL_RED_JS), 120.0,
                                  "drawing with WebGL")
        types = page.process_types()
    assert "SwiftShader" in renderer, renderer
    assert px == [255, 0, 0, 255]
    assert "browser" in types and "renderer" in types, types
    assert "gpu-process" not in types, types


def _until(pred, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")


def test_view_follows_the_aircraft_far_from_home(chromium, far_flight, tmp_path):
    """Fixed-wing, hundreds of metres from home: every screenshot shows the aircraft in the
    middle of a rendered 3-D view (sky above the horizon, no blank band) and the panel."""
    from support.browser import DashboardPage

    dash, ap = far_flight
    with DashboardPage(dash.page_url, width=1100, height=720, max_fps=10.0) as page:
        page.wait(lambda s: s["link"] == "ok", 180, "the link")
        _until(lambda: dash.gs.arm().accepted, 60, "arming")
        _until(lambda: dash.gs.takeoff(30.0).accepted, 60, "the takeoff")
        _until(lambda: ap.stage == "hover", 120, "the hover")
        _until(lambda: dash.gs.transition("fw").accepted, 60, "the transition")
        page.wait(lambda s: float(s["north"]) > 300.0 and s["vtol"] == "FW", 240,
                  "the aircraft 300 m north in the page")
        panel_left = page._call(lambda: page.driver.execute_script(_PANEL_LEFT_JS), 180.0,
                                "the panel's position")
        assert panel_left is not None and 500 < panel_left < 1100, panel_left
        # the first rendered frame may take a while on a loaded machine; after that, every
        # screenshot must pass
        problems: list[str] = []
        deadline = time.monotonic() + 240.0
        while time.monotonic() < deadline:
            problems = view_problems(page.screenshot_array(), panel_left)
            if not problems:
                break
            time.sleep(1.0)
        assert not problems, problems
        north0 = float(page.status()["north"])
        for k in range(3):
            time.sleep(2.0)
            img = page.screenshot_array()
            Image.fromarray(img).save(tmp_path / f"far_{k}.png")
            assert view_problems(img, panel_left) == [], (k, view_problems(img, panel_left))
        north1 = float(_until(page.status, 60, "the status")["north"])
        print(f"\nfollowed the aircraft from {north0:.0f} m to {north1:.0f} m north: "
              f"{tmp_path}")
        assert north1 > north0 + 10.0                     # it kept flying away meanwhile


# Under load (session 13, 2 burners + 4 other helpers, load 11-16, CPU PSI "some" 97-99 %) this
# test failed like the lead's loaded CI run: "the renderer did not answer within 180 s" at its
# first status read (455 s in all). What the renderer did meanwhile, measured:
# - the page's renderer process used ~1 % of a core, its main thread in a futex wait (gdb:
#   pthread_cond_wait), so it was blocked, not busy: a CDP Runtime.evaluate of
#   ``document.readyState`` on a second DevTools connection got no answer in 120 s;
# - the GPU process (SwiftShader, where WebGL runs) used 5-10 % of a core: its main thread
#   waited in libvk_swiftshader.so, its two marl workers (Thread<00>, Thread<01>) were in
#   sched_yield in every one of 6 gdb samples;
# - replacing the setTimeout frame cap below by one that keeps the real requestAnimationFrame
#   (the compositor's back-pressure) changed nothing at that point: the page was stuck before
#   its first frame either way, so frame pacing is not (or not alone) the cause;
# - a [Processor] ThreadCount=1 SwiftShader.ini in the GPU process's working directory is not
#   read by Debian's chromium 156 (still two workers).
# Found in session 14: Debian's chromium launcher adds --enable-gpu-rasterization
# (/etc/chromium.d/default-flags), so the whole page - the control panel whose text changes 10
# times a second, not only the WebGL canvas - was rasterised and composited by SwiftShader in
# the starved GPU process, and the renderer waited on it. tests/support/browser.py now starts
# chromium with software raster and compositing and the GPU service in-process (measured
# figures there); --disable-gpu-rasterization alone was not enough (no link in 160 s).
def test_transition_from_the_browser(chromium, sitl, tmp_path):
    from support.browser import DashboardPage

    _run, dash = sitl
    # SwiftShader renders every frame in software: at 60 frames/s of a large canvas the page
    # alone takes most of a core, and on a loaded 2-core machine it starves its own renderer
    # (and the real-time SITL) for minutes; 10 frames/s of a smaller window still show the
    # aircraft move (the scene-change check below)
    with DashboardPage(dash.page_url, width=1100, height=720, max_fps=10.0) as page:
        st = page.wait(lambda s: s["link"] == "ok" and float(s["altitude"]) >= 0.0, 30,
                       "the autopilot link")
        assert st["vtol"] == "MC" and st["armed"] == "0"
        page.wait(lambda s: page.driver.execute_script(
            "return document.querySelectorAll('canvas').length") > 0, 180, "the 3-D canvas")

        below0 = page._call(lambda: page.driver.execute_script(_BUTTONS_BELOW_STATUS_JS),
                            180.0, "the buttons' position")
        # the autopilot refuses a transition on the ground: the page must say so
        state, text, _ = page.press("Transition to fixed-wing")
        assert state == "refused" and "DENIED" in text, text

        page.press_until_accepted("Arm", 120)       # refused until navigation data arrive
        page.press_until_accepted("Takeoff", 60)
        page.wait(lambda s: s["mode"] == "AUTO.LOITER" and float(s["altitude"]) > 25.0, 120,
                  "the end of the climb (hover at 30 m)")
        before = page.wait(lambda s: True, 120, "the status before the transition")
        shot_before = page.screenshot_array()

        state, text, _ = page.press("Transition to fixed-wing")
        assert state == "accepted", text
        page.wait(lambda s: s["vtol"] in ("TRANSITION_TO_FW", "FW"), 60,
                  "the VTOL state to leave MC")
        after = page.wait(lambda s: s["vtol"] == "FW", 120, "fixed-wing")
        shot_after = page.screenshot_array()
        # the view followed the aircraft: in the middle of a rendered view, panel shown
        panel_left = page._call(lambda: page.driver.execute_script(_PANEL_LEFT_JS), 180.0,
                                "the panel's position")
        problems = view_problems(shot_after, panel_left)
        deadline = time.monotonic() + 240.0
        while problems and time.monotonic() < deadline:
            time.sleep(1.0)
            shot_after = page.screenshot_array()
            problems = view_problems(shot_after, panel_left)
        assert not problems, problems
        # the status panel kept its height through the flight's texts (an autopilot message,
        # longer lines): the buttons did not move under the pointer
        below1 = page._call(lambda: page.driver.execute_script(_BUTTONS_BELOW_STATUS_JS),
                            180.0, "the buttons' position")
        assert below0 is not None and len(below0) == 3 and below1 == below0, (below0, below1)
        path = page.screenshot(tmp_path / "dashboard_after_transition.png")
        print(f"\nscreenshot: {path}")
        if os.environ.get("VTOLFTC_ARTIFACTS"):          # CI: keep it beyond pytest's tmp
            keep = Path(os.environ["VTOLFTC_ARTIFACTS"]) / path.name
            keep.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, keep)
            print(f"screenshot copied to {keep}")

        # the aircraft moved: north position and airspeed in the page, and the 3-D view
        assert float(after["north"]) - float(before["north"]) > 20.0, (before, after)
        assert float(after["airspeed"]) > 12.0
        assert _scene_change(shot_before, shot_after) > 0.01
        assert int(after["update"]) > int(before["update"])
        assert path.stat().st_size > 10_000
        print(f"clicks the driver sent that missed their button (repeated): "
              f"{page.missed_clicks or 'none'}")

        # the page stays live after the transition; its update *rate* is a speed figure and
        # lives in benchmarks/bench_dashboard.py (a software-rendered WebGL page beside a
        # real-time SITL on 2 shared cores is no place for a wall-clock threshold)
        page.start_update_counter()
        n, dt = 0, 0.0
        deadline = time.monotonic() + 30.0
        while n == 0 and time.monotonic() < deadline:
            time.sleep(1.0)
            n, dt = page.update_rate()
        print(f"page updates: {n} in {dt:.1f} s (dashboard rate 10 /s)")
        assert n > 0, "the page stopped updating after the transition"
    assert Path(path).exists()
