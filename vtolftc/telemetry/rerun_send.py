"""The flushing part of a rerun recording: buffered rows to rerun in columns, and the writes.

:class:`ColumnSender` sends a :class:`~vtolftc.telemetry.rerun_rows.RowBuffer` with one
``send_columns`` call per entity (angles in degrees, the display edge), sends the flown path at
most every ``path_period_usec`` of simulated time and then waits for rerun's writer.

The flown path is cut into segments of at most ``path_segment_points`` points, one entity
each (``world/path/00000``, ``world/path/00001``, ...; :func:`path_segment_entity`): only the
open segment is re-sent, a full one stays as it was last logged and the next starts at its last
point. So the memory and the bytes per send stay bounded however long the run, and the viewer
(latest value of every segment) still shows the whole path flown up to its time cursor.
:class:`BackgroundFlusher` asks rerun every 0.25 s of wall time to write what it holds
(events logged while the simulation stands still).
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from vtolftc.base.rotation import ATTITUDE_AXES
from vtolftc.telemetry.rerun_rows import RowBuffer
from vtolftc.telemetry.rerun_scene import TIMELINE, actuator_entity

__all__ = ["BackgroundFlusher", "ColumnSender", "ScalarColumn", "flush_takes_timeout",
           "path_segment_entity"]

#: Entity path of the flown path's segments (``world/path/NNNNN``).
PATH_ENTITY = "world/path"


def path_segment_entity(index: int) -> str:
    """Entity of the flown path's segment ``index`` (0, 1, ...): ``world/path/00000``, ..."""
    return f"{PATH_ENTITY}/{index:05d}"


def flush_takes_timeout(rec: Any) -> bool:
    """Whether ``rec.flush`` of this rerun version accepts ``timeout_sec``."""
    import inspect

    try:
        return "timeout_sec" in inspect.signature(rec.flush).parameters
    except (TypeError, ValueError):
        return False


class ScalarColumn:
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


class ColumnSender:
    """Sends buffered rows to a rerun recording stream (see the module docstring).

    Parameters
    ----------
    rr
        the ``rerun`` module.
    rec
        the ``rerun.RecordingStream``.
    path_period_usec
        simulated time between two sends of the flown path [us].
    path_segment_points
        points of the flown path per segment entity (at least 2).
    wait
        called after each send but the final one to have rerun write the rows (default:
        ``rec.flush``, blocking until written; :meth:`BackgroundFlusher.request` hands the wait
        to that thread).
    """

    def __init__(self, rr: Any, rec: Any, path_period_usec: int,
                 path_segment_points: int = 250, wait: Any = None) -> None:
        self._rr = rr
        self._rec = rec
        self.wait = wait
        """The writes' wait after a send (None: ``rec.flush`` in the caller's thread)."""
        self._path_period_usec = path_period_usec
        self._last_path_usec: int | None = None
        self._seg_cap = max(2, int(path_segment_points))
        self._seg: list[tuple[float, float, float]] = []     # the open segment, NED [m]
        self._seg_index = 0
        self._seg_dirty = False
        self._last_row_usec = 0                               # time of the last row sent
        self._scalar_desc: Any = None
        self._flush_timeout = flush_takes_timeout(rec)

    def _scalar_descriptor(self) -> Any:
        """The component descriptor of ``Scalars:scalars`` (looked up once)."""
        desc = self._scalar_desc
        if desc is None:
            col = next(iter(self._rr.Scalars.columns(scalars=np.zeros(1))))
            desc = self._scalar_desc = col.component_descriptor()
        return desc

    def send(self, rows: RowBuffer, names: Sequence[str], final: bool = False) -> None:
        """Send the ``rows.n`` buffered rows as columns (``names`` the actuators), the path
        when due (always when ``final``), and (unless ``final``) wait until rerun has written
        them. Errors are printed, never raised; the caller resets the buffer."""
        for _ in self.pieces(rows, names, final):
            pass

    def pieces(self, rows: RowBuffer, names: Sequence[str],
               final: bool = False) -> Iterator[None]:
        """:meth:`send` cut into pieces: a generator that sends one entity's column (tens of
        microseconds) per ``next``. ``rows`` must stay unchanged until it is exhausted (a
        :meth:`RowBuffer.copy`)."""
        n = rows.n
        if n == 0:
            if final:
                try:
                    self._send_path(self._last_row_usec, rows.path_pts, final)
                except Exception as exc:
                    print(f"rerun recorder: flush: {exc}", file=sys.stderr)
            return
        rr = self._rr
        rec = self._rec
        try:
            times = [rr.TimeColumn(TIMELINE,
                                   duration=(rows.t[:n] * 1000).astype("timedelta64[ns]"))]

            scalar_desc = self._scalar_descriptor()

            def scalars(entity: str, values: np.ndarray) -> None:
                # the arrow list column rr.Scalars.columns(...).partition(...) builds, made
                # directly (a fraction of the cost: this runs for every entity and chunk)
                width = values.shape[1] if values.ndim == 2 else 1
                flat = pa.array(np.ascontiguousarray(values, dtype=np.float64).ravel())
                offsets = pa.array(np.arange(0, (n + 1) * width, width, dtype=np.int32))
                rec.send_columns(entity, indexes=times, columns=[
                    ScalarColumn(scalar_desc, pa.ListArray.from_arrays(offsets, flat))])

            b = rows.buf[:n]
            sl = rows.sl
            att_ref = np.degrees(b[:, sl["att_ref"]])
            att = np.degrees(b[:, sl["att"]])
            for j, ax in enumerate(ATTITUDE_AXES):
                scalars(f"attitude/{ax}", np.column_stack((att_ref[:, j], att[:, j])))
                yield
            misc = b[:, sl["misc"]]
            scalars("altitude", misc[:, [1, 0]])
            yield
            scalars("airspeed", misc[:, [2, 3]] if rows.has_truth else misc[:, 2])
            scalars("mode/id", misc[:, 4])
            scalars("mode/armed", misc[:, 5])
            yield
            scalars("control/virtual", b[:, sl["virt"]])
            yield
            cmd = b[:, sl["cmd"]]
            eff = b[:, sl["eff"]]
            for j, name in enumerate(names):
                scalars(actuator_entity(name),
                        np.column_stack((cmd[:, j], eff[:, j])) if rows.has_truth
                        else cmd[:, j])
                yield
            q = b[:, sl["q"]]
            rec.send_columns("world/aircraft", indexes=times, columns=rr.Transform3D.columns(
                translation=b[:, sl["pos"]], quaternion=q[:, [1, 2, 3, 0]]))
            yield
            self._last_row_usec = int(rows.t[n - 1])
            self._send_path(self._last_row_usec, rows.path_pts, final)
            if not final and self.wait is not None:
                self.wait()  # e.g. the flusher thread writes now, this thread goes on
            elif not final:
                # rerun writes the file from its own threads, later by wall-clock time: wait
                # for it here, on simulated time, so a SIGKILL loses about file_flush_sim_s
                # however fast the simulation runs
                rec.flush(timeout_sec=1.0) if self._flush_timeout else rec.flush()
        except Exception as exc:
            print(f"rerun recorder: flush: {exc}", file=sys.stderr)

    def _send_path(self, t_last: int, pts: list[tuple[float, float, float]],
                   final: bool) -> None:
        """Take the new path points ``pts`` (NED, m; the list is emptied) into the open
        segment, log every segment that fills up, and the open one when due (at ``t_last``
        [us]; always when ``final``)."""
        seg = self._seg
        for p in pts:
            seg.append(p)
            self._seg_dirty = True
            if len(seg) >= self._seg_cap:          # full: its last form, then the next one
                self._log_segment(t_last)
                self._seg_index += 1
                seg = self._seg = [p]               # starts where the last one ended
        pts.clear()
        if self._seg_dirty and (final or self._last_path_usec is None
                                or t_last - self._last_path_usec >= self._path_period_usec):
            self._last_path_usec = t_last
            self._log_segment(t_last)

    def _log_segment(self, t_usec: int) -> None:
        """Log the open segment at ``t_usec`` [us] on its entity."""
        self._rec.set_time(TIMELINE, duration=np.timedelta64(t_usec * 1000, "ns"))
        self._rec.log(path_segment_entity(self._seg_index),
                      self._rr.LineStrips3D([self._seg], colors=(250, 200, 40), radii=0.05))
        self._seg_dirty = False


class BackgroundFlusher:
    """A daemon thread asking rerun to write what it holds every 0.25 s of wall time, and at
    once on :meth:`request` (``rec.flush`` releases the GIL while rerun's threads write: the
    caller's thread runs on meanwhile).

    Parameters
    ----------
    rec
        the ``rerun.RecordingStream``.
    finished
        tells whether the recording is closed (the thread then ends on an error).
    """

    def __init__(self, rec: Any, finished: Any) -> None:
        self._rec = rec
        self._finished = finished
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True, name="rerun-flush")
        self._thread.start()

    def request(self) -> None:
        """Have the thread ask rerun to write now (returns at once)."""
        self._wake.set()

    def _loop(self) -> None:
        """Every 0.25 s of wall time or on :meth:`request`, ask rerun to write what it holds
        (events logged while the simulation stands still, the rows just sent); a slow write
        (timeout) is tried again next time."""
        timeout = flush_takes_timeout(self._rec)
        while True:
            self._wake.wait(0.25)
            self._wake.clear()
            if self._stop.is_set():
                return
            try:
                self._rec.flush(timeout_sec=1.0) if timeout else self._rec.flush()
            except Exception:  # a timeout on a loaded machine: keep going
                if self._finished():
                    return

    def stop(self) -> None:
        """Stop the thread (waits up to 2 s for it)."""
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
