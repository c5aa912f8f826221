"""Watch a real-time SITL from outside and say what its processes did when the flight stalled.

A real-time flight that stops (no control step for seconds: the vehicle's output watchdog cuts
the rotors after ``--output-timeout``) leaves only its summaries behind, which say *that* the
loop did not step, not *why*. :class:`StallProbe` samples, every ``period_s`` (wall clock), the
flight's progress (a callable: the simulated time the ground station last saw, s) and, from
``/proc``, every thread of the watched processes (scheduler state, CPU time, kernel wait
channel) and the machine (load average, pressure stall figures). When the progress stands
still for ``stall_s`` it writes a report while the stall lasts: the samples of the last
``history_s`` and each process's Python thread stacks (``py-spy dump``, when installed); when
the progress resumes it adds how long the stall lasted. Linux only (``/proc``); elsewhere it
samples the progress alone.

The probe reads and never writes the processes it watches (``py-spy dump --nonblocking``: it
does not stop the process it reads, so a false alarm cannot make a stall).
"""

from __future__ import annotations

import collections
import contextlib
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from vtolftc.runners.processes.procstate import proc_threads

__all__ = ["Stall", "StallProbe", "proc_threads", "pyspy_dump"]

@dataclass
class Stall:
    """One stall: flight progress stood still from ``start_wall`` (time.monotonic, s)."""

    start_wall: float
    progress: float
    """The progress value that stood still (simulated time, s)."""
    duration_s: float | None = None
    """Wall seconds until the progress moved again (None: it had not when the probe
    stopped)."""
    report: Path | None = None
    first_lines: list[str] = field(default_factory=list)

    def describe(self) -> str:
        d = "not resumed" if self.duration_s is None else f"{self.duration_s:.2f} s"
        return (f"stall at progress {self.progress:.3f} ({d}); report {self.report}: "
                + " | ".join(self.first_lines))


def _machine() -> str:
    parts = []
    with contextlib.suppress(OSError):
        parts.append("load " + " ".join(Path("/proc/loadavg").read_text().split()[:3]))
    for kind in ("cpu", "io", "memory"):
        with contextlib.suppress(OSError):
            some = Path(f"/proc/pressure/{kind}").read_text().splitlines()[0]
            parts.append(f"psi-{kind} {some.split()[1]}")
    return ", ".join(parts)


def pyspy_dump(pid: int, timeout_s: float = 20.0) -> str:
    """Python stacks of every thread of ``pid`` (``py-spy dump --nonblocking``: the process
    is not stopped, a stack may be torn), or why there are none."""
    exe = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
    if not Path(exe).exists():
        return "(py-spy not installed: no Python stacks)"
    try:
        r = subprocess.run([exe, "dump", "--nonblocking", "--pid", str(pid)],
                           capture_output=True, text=True, timeout=timeout_s, check=False)
    except subprocess.TimeoutExpired:
        return f"(py-spy dump of {pid} did not finish in {timeout_s:g} s)"
    return (r.stdout + r.stderr).strip()


class StallProbe:
    """Samples a flight's progress and its processes; reports stalls (see the module doc).

    Parameters
    ----------
    progress
        the flight's progress, non-decreasing while it flies (simulated time, s); called from
        the probe's thread; an exception counts as no sample.
    pids
        name -> process id of the processes to watch (e.g. autopilot, vehicle).
    out_dir
        where the reports go (``stall_<k>.txt``).
    stall_s
        wall seconds without progress that make a stall (keep it under the vehicle's
        watchdog timeout, so the report is written while the stall lasts).
    period_s, history_s
        sampling period and how much history a report shows, wall s.
    max_reports
        reports written at most (later stalls are only counted).
    """

    def __init__(self, progress: Callable[[], float], pids: dict[str, int], out_dir: Path, *,
                 stall_s: float = 2.0, period_s: float = 0.25, history_s: float = 8.0,
                 max_reports: int = 3) -> None:
        self.progress = progress
        self.pids = dict(pids)
        self.out_dir = Path(out_dir)
        self.stall_s = float(stall_s)
        self.period_s = float(period_s)
        self.max_reports = int(max_reports)
        self.stalls: list[Stall] = []
        self._samples: collections.deque[tuple[float, float | None, str]] = \
            collections.deque(maxlen=max(1, round(history_s / period_s)))
        self._prev_cpu: dict[tuple[str, int], float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stall-probe", daemon=True)

    # -- lifetime -----------------------------------------------------------------------
    def start(self) -> StallProbe:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=60.0)

    def __enter__(self) -> StallProbe:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def summary(self) -> str:
        """One line per stall seen ("no stall" when none)."""
        if not self.stalls:
            return "stall probe: no stall"
        return "stall probe: " + "; ".join(s.describe() for s in self.stalls)

    # -- sampling -----------------------------------------------------------------------
    def _threads_line(self) -> str:
        """Per watched process: its threads that used CPU since the last sample or are not
        sleeping, as tid/name:state:cpu-ms[:wchan] (Python < 3.14 names no OS thread: the
        tid is what py-spy's stacks are listed by)."""
        parts = []
        for name, pid in self.pids.items():
            cells = []
            for tid, comm, state, cpu, wchan in proc_threads(pid):
                key = (name, tid)
                d = cpu - self._prev_cpu.get(key, cpu)
                self._prev_cpu[key] = cpu
                if d > 0 or state != "S":
                    cell = f"{tid}/{comm}:{state}:{1e3 * d:.0f}ms"
                    if state != "R":
                        cell += f":{wchan}"
                    cells.append(cell)
            parts.append(f"{name}[{' '.join(cells) or 'all asleep'}]")
        return " ".join(parts)

    def _sample(self) -> float | None:
        try:
            p = float(self.progress())
        except Exception:
            p = None
        now = time.monotonic()
        self._samples.append((now, p, f"{_machine()} {self._threads_line()}"))
        return p

    def _run(self) -> None:
        last_p: float | None = None
        last_change = time.monotonic()
        current: Stall | None = None
        while not self._stop.wait(self.period_s):
            p = self._sample()
            now = time.monotonic()
            if p is None:
                continue
            if last_p is None or p != last_p:
                if current is not None:
                    current.duration_s = now - current.start_wall
                    self._append(current, f"progress moved again after "
                                          f"{current.duration_s:.2f} s (to {p:.3f})")
                    current = None
                last_p, last_change = p, now
                continue
            if current is None and now - last_change >= self.stall_s and p > 0.0:
                current = Stall(start_wall=last_change, progress=p)
                self.stalls.append(current)
                if len(self.stalls) <= self.max_reports:
                    self._report(current, len(self.stalls))

    def _report(self, stall: Stall, k: int) -> None:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        path = self.out_dir / f"stall_{k}.txt"
        t_now = time.monotonic()
        lines = [f"progress stood still at {stall.progress:.3f} for "
                 f"{t_now - stall.start_wall:.2f} s (threshold {self.stall_s:g} s); "
                 f"watched {self.pids}", "", "samples (wall s relative to the stall's start,"
                 " progress, machine, threads: tid/name:state:cpu since last sample[:wchan]):"]
        lines += [f"{t - stall.start_wall:+7.2f} {'-' if p is None else f'{p:.3f}'} {text}"
                  for t, p, text in self._samples]
        lines.append("")
        first = [lines[0]]
        for name, pid in self.pids.items():
            dump = pyspy_dump(pid)
            lines += [f"== Python stacks of {name} (pid {pid}):", dump, ""]
            first.append(f"{name}: " + " / ".join(
                ln.strip() for ln in dump.splitlines()[1:6] if ln.strip()))
        path.write_text("\n".join(lines) + "\n")
        stall.report = path
        stall.first_lines = first

    def _append(self, stall: Stall, text: str) -> None:
        if stall.report is not None:
            with stall.report.open("a") as f:
                f.write(text + "\n")
