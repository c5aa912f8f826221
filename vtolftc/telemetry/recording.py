"""Rerun recording of a run: a :class:`~vtolftc.telemetry.RunObserver` that writes a ``.rrd``.

Every run (in-process, SITL, CI) hands its samples and events to a :class:`RerunRecorder`,
which always writes a ``.rrd`` file and, with ``live=True``, also streams to a viewer (a native
viewer when a display exists, else the rerun web viewer served on 127.0.0.1, whose URL is
printed). Open a file with ``rerun FILE.rrd``.

Timeline: ``sim_time`` (a duration: simulated time since the start of the run, from the
samples' ``time_usec``), never wall-clock.

Entities (angles in degrees, the display edge; everything else SI). Series that belong
together share one entity with several scalars per row (named in a static ``SeriesLines``):
one ``send_columns`` call per entity and chunk is what keeps the recorder cheap.

==============================================  ================================================
``attitude/{roll,pitch,yaw}``                   [reference, actual] (autopilot's view)
``altitude``                                    [reference, actual] above home (m, up positive)
``airspeed``                                    [autopilot, truth] (truth only when known)
``mode/id``, ``mode/state``                     FlightMode value (scalar) and name
                                                (StateChange, logged on change)
``mode/armed``                                  0 / 1
``actuators/{rotors,pushers,surfaces}/NAME``    [command, effective] for every actuator:
                                                normalised command (rotors/pushers 0..1,
                                                surfaces -1..1) and truth position x
                                                effectiveness (only when samples carry truth)
``control/virtual``                             [Fz, Fx, L, M, N] (N, N m)
``events``                                      every event (TextLog)
``faults/log``, ``faults/marker``               fault events: text, and a point whose value
                                                counts the faults so far
``world/aircraft`` (+ ``/shape``, ``/rotors``,  pose (Transform3D in NED) and a static aircraft
``/axes``)                                      of boxes and discs in body FRD
``world/path``                                  flown path (LineStrips3D, about 5 Hz)
``run/info``, ``run/metrics``                   run description and final metrics (static)
==============================================  ================================================

Cost: the flight loop only copies a decimated sample (``rate_hz``, default 50 Hz) into
pre-allocated numpy buffers; the buffers go to rerun in columns (``send_columns``) every
``file_flush_sim_s`` of simulated time (default 0.5 s; also when ``chunk_rows`` rows are
buffered, and at least every ``live_flush_s`` of wall time when live), followed by a blocking
``flush``: rerun writes the file from its own threads on wall-clock time, and a simulation
running at 50x real time outran them (a SIGKILL of ``vtolftc fly`` on an idle machine lost
1.1-5.1 s of simulated time without the wait, 0.12 s with it; the wait costs about 3 ms per
flush, 0.3 s on a 60 s case-1 flight of 3.2 s). What is logged row by row (events, modes,
faults, the path) leaves rerun's batcher within 8 ms of wall time
(``ChunkBatcherConfig.LOW_LATENCY``), and a background thread asks rerun every 0.25 s of wall
time to write what it holds (events logged while the simulation stands still). So a killed
process (SIGKILL) loses about ``file_flush_sim_s`` of simulated time, however fast the
simulation runs against the wall clock, and the file written so far stays readable. The flown path
(``world/path``, the whole path so far each time) is re-sent at most every ``path_period_s``
of simulated time (default 1 s) and at the end.
``benchmarks/bench_dashboard.py`` measures the cost per sample.
"""

from __future__ import annotations

import atexit
import contextlib
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from vtolftc.protocols.hil import N_ACTUATORS
from vtolftc.rotation import ATTITUDE_AXES
from vtolftc.telemetry.autopilot_status import FlightMode
from vtolftc.telemetry.samples import TelemetrySample

__all__ = ["DEFAULT_ACTUATOR_NAMES", "RerunRecorder", "actuator_entity", "read_recording"]

DEFAULT_ACTUATOR_NAMES: tuple[str, ...] = (
    "rotor_1a", "rotor_1b", "rotor_2a", "rotor_2b", "rotor_3a", "rotor_3b", "rotor_4a",
    "rotor_4b", "pusher_left", "pusher_right", "aileron_left", "aileron_right", "elevator",
    "rudder_left", "rudder_right",
)
_AXES = ATTITUDE_AXES
_VIRTUAL = ("Fz", "Fx", "L", "M", "N")
_TIMELINE = "sim_time"


def actuator_entity(name: str) -> str:
    """Entity path prefix of an actuator: ``actuators/<group>/<name>``."""
    if name.startswith("rotor"):
        group = "rotors"
    elif name.startswith("pusher"):
        group = "pushers"
    else:
        group = "surfaces"
    return f"actuators/{group}/{name}"


def _port_open(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class RerunRecorder:
    """A :class:`~vtolftc.telemetry.RunObserver` writing a rerun recording (see module doc).

    Parameters
    ----------
    path
        the ``.rrd`` file to write (parent folders are created).
    live
        also stream to a viewer (native if a display exists, else the web viewer).
    application_id
        rerun application id.
    recording_id
        rerun recording id (default: a fresh UUID).
    rate_hz
        logging rate in simulated time; samples in between are skipped.
    chunk_rows
        rows buffered before they are sent to rerun.
    live_flush_s
        with ``live``, the longest wall-clock wait before buffered rows are sent.
    file_flush_s
        the longest wall-clock wait before buffered rows are sent to the file (for a
        simulation slower than real time).
    file_flush_sim_s
        the longest simulated time buffered before rows are sent and written to the file:
        a killed process loses about this much (see the module docstring).
    path_period_s
        simulated time between two sends of the flown path.
    web_port, grpc_port
        ports of the web viewer and of its data server (live, headless).
    airframe
        airframe for the aircraft shape (default: the shipped DS-1).
    """

    def __init__(self, path: Path, *, live: bool = False, application_id: str = "vtolftc",
                 recording_id: str | None = None, rate_hz: float = 50.0, chunk_rows: int = 500,
                 live_flush_s: float = 0.2, web_port: int = 9090, grpc_port: int = 9876,
                 airframe: Any = None, file_flush_s: float = 0.5,
                 file_flush_sim_s: float = 0.5, path_period_s: float = 1.0) -> None:
        import rerun as rr

        if not rate_hz > 0:
            raise ValueError(f"rate_hz = {rate_hz!r}: expected a positive rate in Hz")
        self._rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.live = live
        self.viewer_url: str | None = None
        self._period_usec = max(1, round(1e6 / rate_hz))
        self._chunk = max(1, int(chunk_rows))
        self._flush_s = min(live_flush_s, file_flush_s) if live else file_flush_s
        # rows spanning this much simulated time are sent (the row period short of the span)
        self._flush_span_usec = max(0, round(file_flush_sim_s * 1e6) - self._period_usec)
        self._path_period_usec = max(0, round(path_period_s * 1e6))
        self._last_path_usec: int | None = None
        self._airframe = airframe
        # rows go out in columns (send_columns, written at once); what is logged row by
        # row (events, modes, faults, the path) leaves rerun's batcher within 8 ms of wall
        # time instead of its default 200 ms (seconds of simulated time in a fast run)
        self._rec = rr.RecordingStream(application_id,
                                       recording_id=recording_id or str(uuid.uuid4()),
                                       batcher_config=rr.ChunkBatcherConfig.LOW_LATENCY())
        self._server: subprocess.Popen[bytes] | None = None
        sinks: list[Any] = [rr.FileSink(str(self.path))]
        if live:
            sinks.append(self._live_sink(web_port, grpc_port))
        self._rec.set_sinks(*sinks, default_blueprint=_blueprint())
        if self._server is not None:
            atexit.register(self._stop_server)     # never leave the server behind
        self._names: tuple[str, ...] = DEFAULT_ACTUATOR_NAMES
        self._started = False
        self._finished = False
        self._next_usec: int | None = None
        self._last_mode: int | None = None
        self._n_faults = 0
        self._path_pts: list[tuple[float, float, float]] = []
        self._path_every = max(1, round(rate_hz / 5.0))    # path at about 5 Hz
        self._rows_total = 0
        self._last_flush_wall = time.monotonic()
        self._alloc(N_ACTUATORS)
        # rerun writes the file from its own threads; this one asks it to every 0.25 s, so a
        # killed process loses at most about file_flush_s + 0.25 s of the recording
        self._flush_timeout = _flush_takes_timeout(self._rec)
        self._flusher_stop = threading.Event()
        self._flusher = threading.Thread(target=self._flush_loop, daemon=True,
                                         name="rerun-flush")
        self._flusher.start()

    # -- setup ---------------------------------------------------------------------------
    def _live_sink(self, web_port: int, grpc_port: int) -> Any:
        """A native viewer if there is a display, else a rerun web-viewer server process
        bound to 127.0.0.1 (gRPC on ``grpc_port``, the page on ``web_port``)."""
        rr = self._rr
        grpc_url = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        if _has_display() and shutil.which("rerun") is not None:
            rr.spawn(port=grpc_port, connect=False, recording=self._rec)
            self.viewer_url = grpc_url
            print(f"rerun viewer spawned ({grpc_url})", file=sys.stderr, flush=True)
            return rr.GrpcSink(grpc_url)
        self._server = subprocess.Popen(
            [sys.executable, "-m", "rerun", "--serve-web", "--bind", "127.0.0.1", "--port",
             str(grpc_port), "--web-viewer-port", str(web_port)],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True)
        deadline = time.monotonic() + 30.0
        while not _port_open(grpc_port):
            if self._server.poll() is not None or time.monotonic() > deadline:
                self._stop_server()
                raise RuntimeError(f"the rerun web viewer did not start on 127.0.0.1:"
                                   f"{grpc_port}/{web_port} (ports in use?)")
            time.sleep(0.1)
        self.viewer_url = f"http://127.0.0.1:{web_port}/?url={grpc_url}"
        print(f"rerun web viewer: {self.viewer_url}", file=sys.stderr, flush=True)
        return rr.GrpcSink(grpc_url)

    def _stop_server(self) -> None:
        p = self._server
        if p is None or p.poll() is not None:
            return
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(p.pid, signal.SIGTERM)
        try:
            p.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=5.0)

    def _alloc(self, n_act: int) -> None:
        """One wide float buffer, a row per logged sample; column slices name the fields."""
        cols: dict[str, int] = {"att_ref": 3, "att": 3, "pos": 3, "q": 4, "virt": 5,
                                "cmd": n_act, "eff": n_act, "misc": 6}
        self._sl: dict[str, slice] = {}
        k = 0
        for name, w in cols.items():
            self._sl[name] = slice(k, k + w)
            k += w
        self._n = 0
        self._t = np.zeros(self._chunk, dtype=np.int64)
        self._buf = np.zeros((self._chunk, k))
        self._has_truth = False

    def _log_static(self) -> None:
        rr = self._rr
        rec = self._rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_DOWN, static=True)   # NED
        try:
            from vtolftc.telemetry.geometry import aircraft_geometry

            af = self._airframe
            if af is None:
                from vtolftc.airframe.loader import load_airframe

                af = load_airframe()
            boxes, discs = aircraft_geometry(af)
        except Exception as exc:  # never break a run for a picture
            rec.log("events", rr.TextLog(f"no aircraft shape: {exc}", level="WARN"), static=True)
            return
        rec.log("world/aircraft/shape", rr.Boxes3D(
            centers=[b.center_m for b in boxes], half_sizes=[tuple(s / 2 for s in b.size_m)
                                                             for b in boxes],
            colors=[b.color for b in boxes], labels=None, fill_mode="solid"), static=True)
        halves = []
        for d in discs:
            ax = np.abs(np.asarray(d.axis))
            halves.append(tuple(0.01 if a > 0.5 else d.radius_m for a in ax))
        rec.log("world/aircraft/rotors", rr.Ellipsoids3D(
            centers=[d.center_m for d in discs], half_sizes=halves,
            colors=[(240, 120, 40) if d.name.startswith("rotor") else (60, 200, 90)
                    for d in discs], fill_mode="solid"), static=True)
        rec.log("world/aircraft/axes", rr.Arrows3D(
            vectors=[(1.0, 0, 0), (0, 0.6, 0), (0, 0, 0.6)],
            colors=[(255, 0, 0), (0, 255, 0), (0, 0, 255)]), static=True)
        rec.log("faults/marker", rr.SeriesPoints(markers="diamond", marker_sizes=8.0,
                                                 colors=(230, 40, 40), names="fault"),
                static=True)
        grey, blue, red = (150, 150, 150), (40, 120, 240), (230, 60, 40)
        for ax in _AXES:
            rec.log(f"attitude/{ax}", rr.SeriesLines(names=[f"{ax} ref", ax],
                                                     colors=[grey, blue]), static=True)
        rec.log("altitude", rr.SeriesLines(names=["altitude ref", "altitude"],
                                           colors=[grey, blue]), static=True)
        rec.log("airspeed", rr.SeriesLines(names=["airspeed (autopilot)", "airspeed (truth)"],
                                           colors=[blue, grey]), static=True)
        rec.log("control/virtual", rr.SeriesLines(names=list(_VIRTUAL)), static=True)
        for name in self._names:
            rec.log(actuator_entity(name), rr.SeriesLines(
                names=[f"{name} command", f"{name} effective"], colors=[blue, red]),
                static=True)

    # -- RunObserver ---------------------------------------------------------------------
    def on_start(self, info: dict[str, Any]) -> None:
        """Record the run's description and the static scene (aircraft shape, frames)."""
        if self._started:
            return
        self._started = True
        names = info.get("actuator_names")
        if names:
            self._names = tuple(str(n) for n in names)
            if len(self._names) != self._sl["cmd"].stop - self._sl["cmd"].start:
                self._alloc(len(self._names))
        af = info.get("airframe_obj")
        if af is not None:
            self._airframe = af
        try:
            self._log_static()
            text = "\n".join(f"- **{k}**: {v}" for k, v in info.items() if k != "airframe_obj")
            self._rec.log("run/info", self._rr.TextDocument(text, media_type="text/markdown"),
                          static=True)
        except Exception as exc:  # a recorder must not break the run
            print(f"rerun recorder: on_start: {exc}", file=sys.stderr)

    def on_sample(self, sample: TelemetrySample) -> None:
        """Buffer a sample (decimated to ``rate_hz``); send a chunk when the buffer is full."""
        if self._finished:
            return
        if not self._started:
            self.on_start({})
        t = int(sample.time_usec)
        if self._next_usec is not None and t < self._next_usec:
            return
        # one row per rate_hz grid cell of simulated time (a step that skipped ahead, as a
        # loaded SITL autopilot does, still logs the cell it lands in)
        self._next_usec = (t // self._period_usec + 1) * self._period_usec
        st = sample.status
        nav = sample.nav
        tr = sample.truth
        i = self._n
        row = self._buf[i]
        sl = self._sl
        self._t[i] = t
        row[sl["att_ref"]] = st.attitude_ref_rad
        row[sl["att"]] = st.attitude_rad
        row[sl["virt"]] = st.virtual_command[:5]
        row[sl["cmd"]] = st.actuator_commands
        mode = int(st.mode)
        if tr is not None:
            self._has_truth = True
            pos, q = tr.pos_ned_m, tr.q_wxyz
            row[sl["eff"]] = tr.actuator_positions * tr.effectiveness
            air_true = tr.airspeed_m_s
        else:
            pos, q = nav.pos_ned_m, nav.q_wxyz
            row[sl["eff"]] = np.nan
            air_true = math.nan
        row[sl["pos"]] = pos
        row[sl["q"]] = q
        row[sl["misc"]] = (-pos[2], st.altitude_ref_m, st.airspeed_m_s, air_true, mode,
                           1.0 if st.armed else 0.0)
        if self._rows_total % self._path_every == 0:
            self._path_pts.append((float(pos[0]), float(pos[1]), float(pos[2])))
        self._rows_total += 1
        self._n = i + 1
        if mode != self._last_mode:
            self._last_mode = mode
            self._log_mode(t, mode)
        if (self._n >= self._chunk or t - int(self._t[0]) >= self._flush_span_usec
                or time.monotonic() - self._last_flush_wall > self._flush_s):
            self._flush()

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        """Log an event; fault events also as a marker on ``faults/marker``."""
        if self._finished:
            return
        try:
            rr = self._rr
            self._rec.set_time(_TIMELINE, duration=np.timedelta64(int(time_usec) * 1000, "ns"))
            level = {"fault": "WARN", "warning": "WARN", "error": "ERROR"}.get(kind, "INFO")
            self._rec.log("events", rr.TextLog(f"[{kind}] {text}", level=level))
            if kind == "fault":
                self._n_faults += 1
                self._rec.log("faults/log", rr.TextLog(text, level="WARN"))
                self._rec.log("faults/marker", rr.Scalars(float(self._n_faults)))
        except Exception as exc:
            print(f"rerun recorder: on_event: {exc}", file=sys.stderr)

    def on_finish(self, metrics: dict[str, Any]) -> None:
        """Send what is buffered, the metrics and the path; flush and close the file."""
        if self._finished:
            return
        self._stop_flusher()
        try:
            self._flush(final=True)
            rr = self._rr
            if metrics:
                lines = []
                for k, v in metrics.items():
                    lines.append(f"- **{k}**: {v:.6g}" if isinstance(v, float)
                                 else f"- **{k}**: {v}")
                self._rec.log("run/metrics", rr.TextDocument("\n".join(lines),
                                                             media_type="text/markdown"),
                              static=True)
            self._rec.flush(timeout_sec=10.0) if _flush_takes_timeout(self._rec) \
                else self._rec.flush()
        except Exception as exc:
            print(f"rerun recorder: on_finish: {exc}", file=sys.stderr)
        finally:
            self._finished = True
            try:
                self._rec.disconnect()      # the file is complete; a live server keeps its data
            except Exception as exc:
                print(f"rerun recorder: on_finish: {exc}", file=sys.stderr)

    def _flush_loop(self) -> None:
        """Every 0.25 s of wall time, ask rerun to write what it holds (events logged while
        the simulation stands still); a slow write (timeout) is tried again next time."""
        timeout = _flush_takes_timeout(self._rec)
        while not self._flusher_stop.wait(0.25):
            try:
                self._rec.flush(timeout_sec=1.0) if timeout else self._rec.flush()
            except Exception:  # a timeout on a loaded machine: keep going
                if self._finished:
                    return

    def _stop_flusher(self) -> None:
        self._flusher_stop.set()
        if self._flusher.is_alive() and self._flusher is not threading.current_thread():
            self._flusher.join(timeout=2.0)

    def close(self) -> None:
        """Disconnect from every sink (the file is complete afterwards) and stop the web
        viewer server started for ``live`` (a spawned native viewer stays open). Idempotent."""
        self._stop_flusher()
        try:
            self._rec.disconnect()
        except Exception as exc:
            print(f"rerun recorder: close: {exc}", file=sys.stderr)
        self._stop_server()

    def wait_viewer(self) -> None:
        """Block until Ctrl-C while the live web viewer keeps serving the recording (for a
        CLI that wants the viewer to outlive the run); then stop it. No-op without one."""
        if self._server is None:
            return
        print(f"rerun web viewer still serving at {self.viewer_url} (Ctrl-C to stop)",
              file=sys.stderr, flush=True)
        try:
            while self._server.poll() is None:
                time.sleep(0.5)
        except KeyboardInterrupt:
            pass
        finally:
            self._stop_server()

    # -- internals -----------------------------------------------------------------------
    def _log_mode(self, t_usec: int, mode: int) -> None:
        rr = self._rr
        try:
            name = FlightMode(mode).name
        except ValueError:
            name = str(mode)
        self._rec.set_time(_TIMELINE, duration=np.timedelta64(t_usec * 1000, "ns"))
        self._rec.log("mode/state", rr.StateChange(state=name))
        self._rec.log("events", rr.TextLog(f"[mode] {name}", level="INFO"))

    def _scalar_descriptor(self) -> Any:
        """The component descriptor of ``Scalars:scalars`` (looked up once)."""
        desc = getattr(self, "_scalar_desc", None)
        if desc is None:
            col = next(iter(self._rr.Scalars.columns(scalars=np.zeros(1))))
            desc = self._scalar_desc = col.component_descriptor()
        return desc

    def _flush(self, final: bool = False) -> None:
        """Send the buffered rows to rerun as columns, wait until rerun has written them, and
        reset the buffers; the path too, every ``path_period_s`` and at the end."""
        n = self._n
        self._last_flush_wall = time.monotonic()
        if n == 0:
            return
        rr = self._rr
        rec = self._rec
        try:
            times = [rr.TimeColumn(_TIMELINE,
                                   duration=(self._t[:n] * 1000).astype("timedelta64[ns]"))]

            scalar_desc = self._scalar_descriptor()

            def scalars(entity: str, values: np.ndarray) -> None:
                # the arrow list column rr.Scalars.columns(...).partition(...) builds, made
                # directly (a fraction of the cost: this runs for every entity and chunk)
                width = values.shape[1] if values.ndim == 2 else 1
                flat = pa.array(np.ascontiguousarray(values, dtype=np.float64).ravel())
                offsets = pa.array(np.arange(0, (n + 1) * width, width, dtype=np.int32))
                rec.send_columns(entity, indexes=times, columns=[
                    _Column(scalar_desc, pa.ListArray.from_arrays(offsets, flat))])

            b = self._buf[:n]
            sl = self._sl
            att_ref = np.degrees(b[:, sl["att_ref"]])
            att = np.degrees(b[:, sl["att"]])
            for j, ax in enumerate(_AXES):
                scalars(f"attitude/{ax}", np.column_stack((att_ref[:, j], att[:, j])))
            misc = b[:, sl["misc"]]
            scalars("altitude", misc[:, [1, 0]])
            scalars("airspeed", misc[:, [2, 3]] if self._has_truth else misc[:, 2])
            scalars("mode/id", misc[:, 4])
            scalars("mode/armed", misc[:, 5])
            scalars("control/virtual", b[:, sl["virt"]])
            cmd = b[:, sl["cmd"]]
            eff = b[:, sl["eff"]]
            for j, name in enumerate(self._names):
                scalars(actuator_entity(name),
                        np.column_stack((cmd[:, j], eff[:, j])) if self._has_truth
                        else cmd[:, j])
            q = b[:, sl["q"]]
            rec.send_columns("world/aircraft", indexes=times, columns=rr.Transform3D.columns(
                translation=b[:, sl["pos"]], quaternion=q[:, [1, 2, 3, 0]]))
            t_last = int(self._t[n - 1])
            if self._path_pts and (final or self._last_path_usec is None
                                   or t_last - self._last_path_usec >= self._path_period_usec):
                self._last_path_usec = t_last
                rec.set_time(_TIMELINE, duration=np.timedelta64(t_last * 1000, "ns"))
                pts = self._path_pts
                if len(pts) > 4000:           # keep a long run's path light
                    pts = [*pts[::math.ceil(len(pts) / 4000)], pts[-1]]
                rec.log("world/path", rr.LineStrips3D([pts], colors=(250, 200, 40),
                                                      radii=0.05))
            if not final:
                # rerun writes the file from its own threads, later by wall-clock time: wait
                # for it here, on simulated time, so a SIGKILL loses about file_flush_sim_s
                # however fast the simulation runs
                rec.flush(timeout_sec=1.0) if self._flush_timeout else rec.flush()
        except Exception as exc:
            print(f"rerun recorder: flush: {exc}", file=sys.stderr)
        finally:
            self._n = 0


class _Column:
    """A ready component column for ``send_columns``: its descriptor and arrow list array."""

    __slots__ = ("_array", "_desc")

    def __init__(self, desc: Any, array: Any) -> None:
        self._desc = desc
        self._array = array

    def component_descriptor(self) -> Any:
        """The component descriptor."""
        return self._desc

    def as_arrow_array(self) -> Any:
        """One list (the scalars of a row) per row."""
        return self._array


def _flush_takes_timeout(rec: Any) -> bool:
    import inspect

    try:
        return "timeout_sec" in inspect.signature(rec.flush).parameters
    except (TypeError, ValueError):
        return False


def _blueprint() -> Any:
    """Default layout: 3-D view, attitude/altitude/airspeed plots, mode, actuators, events."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(name="pose and path", origin="world"),
                rrb.StateTimelineView(name="flight mode", origin="mode/state"),
                rrb.TextLogView(name="events", origin="events"),
                row_shares=[3, 1, 2],
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="roll (deg)", origin="attitude/roll"),
                rrb.TimeSeriesView(name="pitch (deg)", origin="attitude/pitch"),
                rrb.TimeSeriesView(name="yaw (deg)", origin="attitude/yaw"),
                rrb.TimeSeriesView(name="altitude (m)", origin="altitude"),
                rrb.TimeSeriesView(name="airspeed (m/s)", origin="airspeed"),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="lift rotors", origin="actuators/rotors"),
                rrb.TimeSeriesView(name="pushers", origin="actuators/pushers"),
                rrb.TimeSeriesView(name="surfaces", origin="actuators/surfaces"),
                rrb.TimeSeriesView(name="faults", origin="faults"),
            ),
            column_shares=[3, 2, 2],
        ),
        collapse_panels=False,
    )


def read_recording(path: Path | str, entities: Sequence[str] | None = None,
                   ) -> dict[str, tuple[np.ndarray, Any]]:
    """Read the time series of a ``.rrd`` file: ``{entity_path: (times_s, values)}``.

    ``times_s`` is the ``sim_time`` timeline in seconds (sorted); ``values`` is a float array
    (one column per scalar, squeezed to 1-D when single) for numeric data, else a list of
    Python values (texts, states, transforms' translations). Entity paths have no leading
    slash. Static data and entities without a ``sim_time`` timeline are not included. Works
    also on files of an interrupted run (no footer).
    """
    from rerun.chunk import RrdReader

    parts: dict[str, list[tuple[np.ndarray, list[Any]]]] = {}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*no footer.*")   # interrupted runs
        reader = RrdReader(str(path))
    for ch in reader.stream():
        if ch.is_static or _TIMELINE not in ch.timeline_names:
            continue
        ent = ch.entity_path.lstrip("/")
        if entities is not None and ent not in entities:
            continue
        rb = ch.to_record_batch()
        names = rb.schema.names
        t = rb.column(names.index(_TIMELINE)).cast("int64").to_numpy(zero_copy_only=False)
        data_cols = [n for n in names if n not in ("rerun.controls.RowId", "log_time", _TIMELINE)]
        preferred = [n for n in data_cols if n.endswith((":scalars", ":text", ":state",
                                                         ":translation", ":strips"))]
        col = (preferred or data_cols or [None])[0]
        if col is None:
            continue
        vals = rb.column(names.index(col)).to_pylist()
        parts.setdefault(ent, []).append((t, vals))
    out: dict[str, tuple[np.ndarray, Any]] = {}
    for ent, chunks in parts.items():
        t = np.concatenate([c[0] for c in chunks])
        vals: list[Any] = [v for c in chunks for v in c[1]]
        order = np.argsort(t, kind="stable")
        ts = t[order] * 1e-9
        vs = [vals[i] for i in order]
        numeric = all(isinstance(v, list) and v and all(isinstance(x, (int, float)) for x in v)
                      for v in vs) and len(vs) > 0
        if numeric:
            arr = np.array(vs, dtype=float)
            out[ent] = (ts, arr[:, 0] if arr.shape[1] == 1 else arr)
        else:
            out[ent] = (ts, [v[0] if isinstance(v, list) and len(v) == 1 else v for v in vs])
    return out
