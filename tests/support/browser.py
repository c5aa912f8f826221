"""Drive the dashboard page in a real headless Chromium (Selenium), for tests and benchmarks.

Uses the system's Chromium and chromedriver (Debian packages ``chromium`` and
``chromium-driver``); nothing is ever downloaded (the driver path is always given, so
Selenium Manager stays out of it). WebGL runs on SwiftShader (software), so the 3-D view
renders without a GPU.

The page exposes its state in ``data-*`` attributes of ``#vtolftc-status`` (link, mode, vtol,
armed, update, north, altitude, airspeed) and the command results in ``#vtolftc-commands``
(see :mod:`vtolftc.dashboard.model`); :class:`DashboardPage` reads them in one script call each.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from support.procs import descendants

__all__ = ["DashboardPage", "find_chromedriver", "find_chromium"]

_STATUS_JS = ("const e = document.getElementById('vtolftc-status');"
              "return e && e.dataset.link ? Object.assign({}, e.dataset) : null;")
_COMMANDS_JS = ("const e = document.getElementById('vtolftc-commands');"
                "if (!e) return [];"
                "return Array.from(e.querySelectorAll('.vtolftc-cmd'))"
                ".map(d => [d.dataset.state, d.innerText, Number(d.dataset.seq)]);")
# Counts, inside the page, how often the displayed update number changes (what the user sees);
# event-driven (MutationObserver), so it adds no polling load to a busy renderer.
_COUNTER_JS = """
window.__vtolftcUpdates = 0; window.__vtolftcLast = null; window.__vtolftcT0 = performance.now();
if (window.__vtolftcObs) window.__vtolftcObs.disconnect();
window.__vtolftcObs = new MutationObserver(() => {
  const e = document.getElementById('vtolftc-status');
  const u = e ? e.dataset.update : null;
  if (u !== null && u !== window.__vtolftcLast) { window.__vtolftcUpdates++;
                                                   window.__vtolftcLast = u; }
});
window.__vtolftcObs.observe(document.body, {childList: true, subtree: true,
                                             attributes: true, attributeFilter: ['data-update']});
"""

# Records, in the capture phase (before the page's own handlers), where every click event of
# the page lands: the label of the button it reached, or "" when it reached no button. While
# ``window.__vtolftcAim`` names a button, a click that lands anywhere else is swallowed (no
# handler of the page sees it), so a click the driver aimed at one button can never act on
# another; the harness reads the log to tell a click that never reached its button (the
# driver's, e.g. the layout moved between its hit test and the mouse events) from a click the
# page received and did not act on (the dashboard's).
_CLICK_LOG_JS = """
if (!window.__vtolftcClickLog) {
  window.__vtolftcClickLog = []; window.__vtolftcAim = null;
  window.addEventListener('click', (e) => {
    const b = e.target && e.target.closest ? e.target.closest('button') : null;
    const label = b ? b.innerText.trim() : '';
    window.__vtolftcClickLog.push(label);
    if (window.__vtolftcAim !== null && label !== window.__vtolftcAim) {
      e.stopPropagation(); e.preventDefault();
    }
  }, true);
}
window.__vtolftcClickLog.length = 0; window.__vtolftcAim = arguments[0];
"""

# Caps requestAnimationFrame at one frame per %g ms (installed before the page's scripts).
_FPS_CAP_JS = """
(() => { const dt = %g; let next = 0;
  window.requestAnimationFrame = (cb) => { const now = performance.now();
    next = Math.max(now, next + dt); return setTimeout(() => cb(performance.now()), next - now); };
  window.cancelAnimationFrame = (id) => clearTimeout(id); })();
"""


# Where the page is drawn. Debian's launcher (/etc/chromium.d/default-flags) adds
# --enable-gpu-rasterization: every tile of the page (the control panel's text changes 10 times
# a second) is then rasterised and composited by SwiftShader in the GPU process, and the
# renderer waits on it. On a loaded 2-core machine that GPU process gets a few % of a core
# (its SwiftShader workers yield-spin) and the renderer's main thread stays blocked for
# minutes (session 13: "the renderer did not answer within 180 s"). So: raster and composite
# in software (Skia on the CPU, no GPU round trip), and run the GPU service - left with only
# the page's WebGL canvas, still on SwiftShader - as a thread of the browser process
# instead of a separately scheduled process. Measured with the kinematic autopilot beside 2
# burners (load 10-12, session 14): default flags, the page never answered a status read in
# 230 s; with these three, status reads answered within 0.63 s (median 0.03 s), 9.2 updates/s
# shown, a screenshot in 0.34 s. The WebGL view itself is unchanged (the screenshot checks).
_WHERE_DRAWN = ("--disable-gpu-rasterization", "--disable-gpu-compositing", "--in-process-gpu")
CHROMIUM_ARGS: tuple[str, ...] = (
    "--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader", "--disable-gpu-sandbox", *_WHERE_DRAWN, "--no-first-run",
    "--disable-extensions", "--disable-background-networking", "--disable-component-update",
    "--disable-sync")


def find_chromium() -> str | None:
    """Path of a Chromium binary (``$CHROMIUM`` first), None if there is none."""
    env = os.environ.get("CHROMIUM")
    if env and Path(env).exists():
        return env
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        p = shutil.which(name)
        if p:
            return p
    return None


def find_chromedriver() -> str | None:
    """Path of chromedriver (``$CHROMEDRIVER`` first), None if there is none."""
    env = os.environ.get("CHROMEDRIVER")
    if env and Path(env).exists():
        return env
    p = shutil.which("chromedriver")
    if p:
        return p
    for cand in ("/usr/lib/chromium/chromedriver", "/usr/bin/chromedriver"):
        if Path(cand).exists():
            return cand
    return None


def _slow() -> tuple[type[BaseException], ...]:
    """What a renderer that does not answer in time raises: chromedriver's TimeoutException
    (after the page-load timeout), or urllib3's ReadTimeoutError when chromedriver itself
    does not answer within Selenium's HTTP read timeout (120 s) on a starved machine. The
    session stays usable: the command is answered later and the next one queues behind."""
    from selenium.common.exceptions import TimeoutException
    from urllib3.exceptions import ReadTimeoutError

    return (TimeoutException, ReadTimeoutError)


class DashboardPage:
    """A headless Chromium showing the dashboard at ``url``.

    Raises
    ------
    RuntimeError
        chromium or chromedriver missing (the message says what to install).
    """

    def __init__(self, url: str, *, width: int = 1400, height: int = 900,
                 timeout_s: float = 60.0, max_fps: float | None = None) -> None:
        from selenium import webdriver
        from selenium.webdriver.chrome.options import Options
        from selenium.webdriver.chrome.service import Service

        chromium, driver = find_chromium(), find_chromedriver()
        if chromium is None:
            raise RuntimeError("no chromium found (apt-get install -y chromium)")
        if driver is None:
            raise RuntimeError("no chromedriver found (apt-get install -y chromium-driver)")
        opts = Options()
        opts.binary_location = chromium
        for a in (*CHROMIUM_ARGS, f"--window-size={width},{height}"):
            opts.add_argument(a)
        self.driver = webdriver.Chrome(service=Service(driver), options=opts)
        self.missed_clicks: list[tuple[str, str]] = []
        # chromedriver gives up on a renderer that does not answer after this timeout
        # (TimeoutException, which the calls below retry); keep it under Selenium's own HTTP
        # read timeout (120 s), which would otherwise fire first as a urllib3 error
        self.driver.set_page_load_timeout(timeout_s)
        self.driver.set_script_timeout(timeout_s)
        if max_fps is not None:
            # every animation frame of the page is a software-rendered WebGL frame: capped,
            # the 3-D view still moves but leaves the CPU to the processes under test
            self.driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument",
                                        {"source": _FPS_CAP_JS % (1000.0 / max_fps)})
        with contextlib.suppress(*_slow()):  # still loading: the waits that follow see it
            self.driver.get(url)

    # -- a renderer that is slow to answer --------------------------------------------------
    def _call(self, fn: Callable[[], Any], timeout_s: float, what: str) -> Any:
        """``fn()``, called again while the renderer does not answer in time (Selenium's
        TimeoutException: software WebGL on a starved CPU can keep the page's renderer busy
        for over a minute); AssertionError saying so after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                return fn()
            except _slow() as e:
                if time.monotonic() >= deadline:
                    raise AssertionError(f"page: the renderer did not answer within "
                                         f"{timeout_s:g} s ({what}): {e}") from e
                time.sleep(0.5)

    # -- reading -------------------------------------------------------------------------
    def status(self) -> dict[str, str] | None:
        """The status panel's data attributes (None before the first update arrived)."""
        return self.driver.execute_script(_STATUS_JS)

    def commands(self) -> list[tuple[str, str, int]]:
        """(state, text, sequence number) of the command results shown, newest first."""
        return [tuple(x) for x in self.driver.execute_script(_COMMANDS_JS)]

    def wait(self, predicate: Callable[[dict[str, str]], bool], timeout_s: float,
             what: str) -> dict[str, str]:
        """Poll the status until ``predicate(status)``; AssertionError with the last status."""
        deadline = time.monotonic() + timeout_s
        st: dict[str, str] | None = None
        while time.monotonic() < deadline:
            try:
                st = self.status()
                if st is not None and predicate(st):
                    return st
            except _slow():
                # the renderer did not answer in time (a starved CPU: software WebGL on a
                # loaded machine); the page is still loading, not wrong: poll again
                pass
            time.sleep(0.1)
        raise AssertionError(f"page: timed out after {timeout_s:g} s waiting for {what}; "
                             f"last status {st}; commands "
                             f"{self._call(self.commands, 180.0, 'the last results')[:3]}")

    # -- acting --------------------------------------------------------------------------
    def click(self, text: str, timeout_s: float = 180.0) -> None:
        """Click the button labelled ``text`` (a real mouse click through the driver) until
        the page has received one click on it: finding it is retried while the renderer is
        slow to answer; a click that the page saw land elsewhere, or not at all, is swallowed
        by :data:`_CLICK_LOG_JS` and repeated, as a user whose click missed clicks again; a
        click whose acknowledgement times out has been dispatched and is not repeated (the
        caller waits for its result).

        Every click that missed is appended to :attr:`missed_clicks` (label, where it landed)."""
        from selenium.common.exceptions import (
            ElementClickInterceptedException,
            StaleElementReferenceException,
        )

        # the panel's layout moves while the status and command texts update (a line more
        # or less above the button): the driver hit-tests the button's centre, then sends the
        # mouse events there, and a layout change in between sends them to whatever slid
        # under that point (chromedriver reports it only when the hit test itself fails);
        # bounded by a count
        try:
            for _ in range(50):
                el = self._call(lambda: self.driver.execute_script(
                    _CLICK_LOG_JS + "const b = Array.from(document.querySelectorAll('button'))"
                    ".find(b => b.innerText.trim() === arguments[0]) || null;"
                    "if (b) { b.scrollIntoView({block: 'center'}); } return b;", text),
                    timeout_s, f"finding the button {text!r}")
                if el is None:
                    raise AssertionError(f"page: no button {text!r}")
                try:
                    el.click()
                except (ElementClickInterceptedException, StaleElementReferenceException):
                    time.sleep(0.2)
                    continue
                except _slow():
                    return                   # dispatched; the page is too busy to say more
                landed: list[str] = []
                for _wait in range(5):       # the driver returns once the events were sent
                    landed = self._call(lambda: self.driver.execute_script(
                        "return window.__vtolftcClickLog.slice();"), timeout_s,
                        f"reading where the click on {text!r} landed")
                    if landed:
                        break
                    time.sleep(0.2)
                if text in landed:
                    return
                self.missed_clicks.append((text, ", ".join(repr(x) for x in landed)
                                           or "no click event"))
                time.sleep(0.2)
            raise AssertionError(f"page: no click reached the button {text!r} in 50 tries "
                                 f"(missed: {self.missed_clicks[-3:]})")
        finally:
            with contextlib.suppress(Exception):
                self.driver.execute_script("window.__vtolftcAim = null;")

    def press(self, button: str, timeout_s: float = 60.0) -> tuple[str, str, int]:
        """Click ``button`` and wait (at most ``timeout_s`` after the click) for the page to
        show the result of the command it sent: (state, text, seq) with state accepted /
        refused / no answer / error."""
        cmds = self._call(self.commands, 180.0, "reading the command results")
        seq0 = cmds[0][2] if cmds else 0
        self.click(button)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                cmds = self.commands()
            except _slow():
                continue                       # a busy renderer: ask again
            new = [c for c in cmds if c[2] > seq0 and c[0] != "pending"]
            if new:
                return new[-1]                 # the oldest new one: this click's
            time.sleep(0.05)
        raise AssertionError(f"page: no result for {button!r} within {timeout_s:g} s of the "
                             f"click: "
                             f"{self._call(self.commands, 60.0, 'the last results')[:3]}; "
                             f"missed clicks before it: {self.missed_clicks}")

    def press_until_accepted(self, button: str, timeout_s: float) -> tuple[str, str, int]:
        """Press ``button`` until its command is accepted (e.g. arming is refused while the
        autopilot has no navigation data yet); returns the accepted result."""
        deadline = time.monotonic() + timeout_s
        res: tuple[str, str, int] | None = None
        while time.monotonic() < deadline:
            res = self.press(button, timeout_s=max(1.0, deadline - time.monotonic()))
            if res[0] == "accepted":
                return res
            time.sleep(0.5)
        raise AssertionError(f"page: {button!r} not accepted within {timeout_s:g} s; last "
                             f"result {res}")

    def start_update_counter(self) -> None:
        """Start counting, in the page, the status updates it displays."""
        self._call(lambda: self.driver.execute_script(_COUNTER_JS), 180.0,
                   "starting the update counter")

    def update_rate(self) -> tuple[int, float]:
        """(updates seen since :meth:`start_update_counter`, seconds elapsed) in the page."""
        n, ms = self._call(lambda: self.driver.execute_script(
            "return [window.__vtolftcUpdates, performance.now() - window.__vtolftcT0];"),
            180.0, "reading the update counter")
        return int(n), float(ms) / 1000.0

    def process_types(self) -> list[str]:
        """The ``--type`` of every live process of this browser (``browser`` for the browser
        process itself; e.g. ``renderer``, ``gpu-process``, ``utility``), by a scan of /proc
        from chromedriver's pid (Linux)."""
        procs = descendants(self.driver.service.process.pid)
        out = []
        for pid in sorted(procs):
            with contextlib.suppress(OSError):
                # chromium rewrites its children's command lines: one space-separated string
                args = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
                args = args.replace("\0", " ").split()
                types = [a[7:] for a in args if a.startswith("--type=")]
                if args and "chrom" in args[0]:
                    out.append(types[0] if types else "browser")
        return out

    def screenshot(self, path: Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self._call(lambda: self.driver.save_screenshot(str(path)), 180.0, "a screenshot")
        return path

    def screenshot_array(self) -> Any:
        """The page as an RGB uint8 array (H, W, 3)."""
        import io

        import numpy as np
        from PIL import Image

        png = self._call(self.driver.get_screenshot_as_png, 180.0, "a screenshot")
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.driver.quit()

    def __enter__(self) -> DashboardPage:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
