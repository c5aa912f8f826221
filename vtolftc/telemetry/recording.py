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
``world/path/NNNNN``                            flown path (LineStrips3D, about 5 Hz), in
                                                segments of ``path_segment_points`` points
``run/info``, ``run/metrics``                   run description and final metrics (static)
==============================================  ================================================

Cost: the flight loop only copies a decimated sample (``rate_hz``, default 50 Hz) into
pre-allocated numpy buffers; the buffers go to rerun in columns (``send_columns``) every
``file_flush_sim_s`` of simulated time (default 0.5 s; also when ``chunk_rows`` rows are
buffered, and at least every ``live_flush_s`` of wall time when live), followed by a blocking
``flush``: rerun writes the file from its own threads on wall-clock time, and a simulation
running at 50x real time outran them (a SIGKILL of ``vtolftc fly`` on an idle machine lost
1.1-5.1 s of simulated time without the wait, 0.12 s with it; the wait costs about 3 ms per
flush, 0.3 s on a 60 s case-1 flight of 3.2 s; ``deferred`` cuts the send into pieces run
while a control loop waits and hands that wait to a background thread instead). What is logged
row by row (events, modes, faults, the path) leaves rerun's batcher within 8 ms of wall time
(``ChunkBatcherConfig.LOW_LATENCY``), and a background thread asks rerun every 0.25 s of wall
time to write what it holds (events logged while the simulation stands still). So a killed
process (SIGKILL) loses about ``file_flush_sim_s`` of simulated time, however fast the
simulation runs against the wall clock, and the file written so far stays readable. The flown path
is cut into segments (``world/path/00000``, ``/00001``, ...; at most ``path_segment_points``
points each, 50 s at the default 5 Hz): the open segment is re-sent at most every
``path_period_s`` of simulated time (default 1 s) and at the end, a full segment is never sent
again, and the viewer, showing the latest value of every segment, draws the whole path flown up
to its time cursor. :func:`~vtolftc.telemetry.rerun_reader.flown_path` joins them back.
``benchmarks/bench_dashboard.py`` measures the cost per sample.

Memory: nothing accumulates per logged row, however long the run (issue 24;
``benchmarks/bench_memory.py``, ``tests/test_memory_sitl.py``). The file is written without
rerun's footer (``FileSink(write_footer=False)``, unless ``write_footer=True``): a footer needs
a manifest entry for every chunk ever written, which rerun keeps in memory until the end, about
3 KB per chunk here (40 chunks per simulated second: 115 KB/s, 400 MB an hour). Without it the
file is still a complete recording that the viewer and :func:`read_recording` open (``python
-m rerun rrd verify --check-footers false``); ``python -m rerun rrd optimize`` adds a footer
afterwards when random access to a huge file matters. The open path segment is the only growing
state, bounded by ``path_segment_points``.

The parts, one job each: :mod:`.rerun_scene` (blueprint, static scene, entity names),
:mod:`.rerun_rows` (per-sample rows), :mod:`.rerun_send` (columns to rerun, the writes),
:mod:`.rerun_viewer` (live viewer) and :mod:`.rerun_reader` (reading a file back).
"""

from __future__ import annotations

import atexit
import collections
import os
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from vtolftc.telemetry.autopilot_status import FlightMode
from vtolftc.telemetry.rerun_reader import read_recording
from vtolftc.telemetry.rerun_rows import RowBuffer
from vtolftc.telemetry.rerun_scene import TIMELINE, actuator_entity, blueprint, log_static_scene
from vtolftc.telemetry.rerun_send import BackgroundFlusher, ColumnSender, flush_takes_timeout
from vtolftc.telemetry.rerun_viewer import LiveViewer
from vtolftc.telemetry.runfolder import actuator_names_of
from vtolftc.telemetry.samples import TelemetrySample

__all__ = ["RerunRecorder", "actuator_entity", "read_recording"]
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
        simulated time between two sends of the flown path's open segment.
    path_segment_points
        points of the flown path per segment entity (bounds the memory and the bytes of a
        send; see the module docstring).
    write_footer
        write rerun's footer at the end (keeps a manifest entry per chunk in memory for the
        whole run: only for short runs; see the module docstring).
    web_port, grpc_port
        ports of the web viewer and of its data server (live, headless).
    airframe
        airframe for the aircraft shape (default: the shipped DS-1).
    deferred
        for a control loop that must not stall 2-7 ms every ``file_flush_sim_s`` (the SITL
        autopilot process, in lockstep): a send is not made in :meth:`on_sample` but cut into
        pieces of one entity each (tens of microseconds) that :meth:`idle_work` runs, one per
        call, while the loop waits; the rows are copied meanwhile, at most one send is
        pending (the next one finishes it first), and the wait for rerun's writes happens in
        the background flusher's thread (``rec.flush`` releases the GIL). A killed process
        then loses about ``file_flush_sim_s`` plus the few milliseconds of wall time the
        pieces and the write take. Default False: the send and the wait in :meth:`on_sample`.
    """

    def __init__(self, path: Path, *, live: bool = False, application_id: str = "vtolftc",
                 recording_id: str | None = None, rate_hz: float = 50.0, chunk_rows: int = 500,
                 live_flush_s: float = 0.2, web_port: int = 9090, grpc_port: int = 9876,
                 airframe: Any = None, file_flush_s: float = 0.5,
                 file_flush_sim_s: float = 0.5, path_period_s: float = 1.0,
                 path_segment_points: int = 250, write_footer: bool = False,
                 deferred: bool = False) -> None:
        if not write_footer and "RUST_LOG" not in os.environ:
            # rerun warns about the missing footer on every run (it is meant: module doc); its
            # logger reads this when rerun is first imported (a later change has no effect);
            # rerun's default level is warn
            os.environ["RUST_LOG"] = "warn,re_log_encoding::rrd::file_sink=error"
        import rerun as rr

        if not rate_hz > 0:
            raise ValueError(f"rate_hz = {rate_hz!r}: expected a positive rate in Hz")
        self._rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.live = live
        self._period_usec = max(1, round(1e6 / rate_hz))
        self._chunk = max(1, int(chunk_rows))
        self._path_every = max(1, round(rate_hz / 5.0))    # path at about 5 Hz
        self._flush_s = min(live_flush_s, file_flush_s) if live else file_flush_s
        # rows spanning this much simulated time are sent (the row period short of the span)
        self._flush_span_usec = max(0, round(file_flush_sim_s * 1e6) - self._period_usec)
        self._airframe = airframe
        # rows go out in columns (send_columns, written at once); what is logged row by
        # row (events, modes, faults, the path) leaves rerun's batcher within 8 ms of wall
        # time instead of its default 200 ms (seconds of simulated time in a fast run)
        self._rec = rr.RecordingStream(application_id,
                                       recording_id=recording_id or str(uuid.uuid4()),
                                       batcher_config=rr.ChunkBatcherConfig.LOW_LATENCY())
        self._viewer = LiveViewer()
        sinks: list[Any] = [rr.FileSink(str(self.path), write_footer=write_footer)]
        if live:
            sinks.append(self._viewer.sink(rr, self._rec, web_port, grpc_port))
        self._rec.set_sinks(*sinks, default_blueprint=blueprint())
        if self._viewer.server is not None:
            atexit.register(self._viewer.stop)     # never leave the server behind
        self._names: tuple[str, ...] = (tuple(airframe.actuator_names)
                                        if airframe is not None else ())
        """Actuator names: the airframe's, or the run's (:meth:`on_start`)."""
        self._started = False
        self._finished = False
        self._next_usec: int | None = None
        self._last_mode: int | None = None
        self._n_faults = 0
        self._last_flush_wall = time.monotonic()
        self._alloc(len(self._names))
        self._sender = ColumnSender(rr, self._rec, max(0, round(path_period_s * 1e6)),
                                    path_segment_points)
        # rerun writes the file from its own threads; this one asks it to every 0.25 s, so a
        # killed process loses at most about file_flush_s + 0.25 s of the recording
        self._flusher = BackgroundFlusher(self._rec, lambda: self._finished)
        self._deferred = deferred
        self._pending: collections.deque[Iterator[None]] = collections.deque()
        """Deferred sends' pieces (at most one send)."""
        if deferred:
            self._sender.wait = self._flusher.request

    @property
    def viewer_url(self) -> str | None:
        """URL of the live viewer (None without one)."""
        return self._viewer.url

    @property
    def _server(self) -> Any:
        """The web-viewer server process started for ``live`` (None without one)."""
        return self._viewer.server

    def _alloc(self, n_act: int) -> None:
        """A fresh row buffer for ``n_act`` actuators (:mod:`.rerun_rows`)."""
        self._rows = RowBuffer(self._chunk, n_act, self._path_every)

    # -- RunObserver ---------------------------------------------------------------------
    def on_start(self, info: dict[str, Any]) -> None:
        """Record the run's description and the static scene (aircraft shape, frames)."""
        if self._started:
            return
        self._started = True
        af = info.get("airframe_obj")
        if af is not None:
            self._airframe = af
        names = info.get("actuator_names") or (
            self._airframe.actuator_names if self._airframe is not None
            else actuator_names_of(info))
        self._names = tuple(str(n) for n in names)
        if len(self._names) != self._rows.n_act:
            self._alloc(len(self._names))
        try:
            log_static_scene(self._rr, self._rec, self._airframe, self._names)
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
        rows = self._rows
        mode = rows.add(t, sample)
        if mode != self._last_mode:
            self._last_mode = mode
            self._log_mode(t, mode)
        if (rows.n >= self._chunk or t - int(rows.t[0]) >= self._flush_span_usec
                or time.monotonic() - self._last_flush_wall > self._flush_s):
            self._flush()

    def idle_work(self) -> bool:
        """``deferred``: run the next piece of the pending send (one entity's column, tens of
        microseconds). True if more pieces remain."""
        pending = self._pending
        if not pending:
            return False
        if next(pending[0], StopIteration) is StopIteration:
            pending.popleft()
        return bool(pending)

    def _finish_pending(self) -> None:
        """Run every pending piece now (a new send, the end of the run)."""
        while self._pending:
            for _ in self._pending.popleft():
                pass

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        """Log an event; fault events also as a marker on ``faults/marker``."""
        if self._finished:
            return
        try:
            rr = self._rr
            self._rec.set_time(TIMELINE, duration=np.timedelta64(int(time_usec) * 1000, "ns"))
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
        self._flusher.stop()
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
            self._rec.flush(timeout_sec=10.0) if flush_takes_timeout(self._rec) \
                else self._rec.flush()
        except Exception as exc:
            print(f"rerun recorder: on_finish: {exc}", file=sys.stderr)
        finally:
            self._finished = True
            try:
                self._rec.disconnect()      # the file is complete; a live server keeps its data
            except Exception as exc:
                print(f"rerun recorder: on_finish: {exc}", file=sys.stderr)

    def close(self) -> None:
        """Disconnect from every sink (the file is complete afterwards) and stop the web
        viewer server started for ``live`` (a spawned native viewer stays open). Idempotent."""
        self._flusher.stop()
        try:
            self._rec.disconnect()
        except Exception as exc:
            print(f"rerun recorder: close: {exc}", file=sys.stderr)
        self._viewer.stop()

    def wait_viewer(self) -> None:
        """Block until Ctrl-C while the live web viewer keeps serving the recording (for a
        CLI that wants the viewer to outlive the run); then stop it. No-op without one."""
        self._viewer.wait()

    # -- internals -----------------------------------------------------------------------
    def _log_mode(self, t_usec: int, mode: int) -> None:
        rr = self._rr
        try:
            name = FlightMode(mode).name
        except ValueError:
            name = str(mode)
        self._rec.set_time(TIMELINE, duration=np.timedelta64(t_usec * 1000, "ns"))
        self._rec.log("mode/state", rr.StateChange(state=name))
        self._rec.log("events", rr.TextLog(f"[mode] {name}", level="INFO"))

    def _flush(self, final: bool = False) -> None:
        """Send the buffered rows to rerun as columns, wait until rerun has written them, and
        reset the buffer; the path too, every ``path_period_s`` and at the end (``deferred``:
        finish the pending send, then queue this one's pieces on a copy of the rows)."""
        self._last_flush_wall = time.monotonic()
        try:
            self._finish_pending()
            if self._deferred and not final:
                self._pending.append(self._sender.pieces(self._rows.copy(), self._names))
            else:
                self._sender.send(self._rows, self._names, final)
        finally:
            self._rows.n = 0
            self._rows.path_pts.clear()     # taken by the sender (or lost with a failed send)
