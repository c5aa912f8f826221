"""The per-sample part of a rerun recording: decimated samples as rows of one numpy buffer.

The flight loop only copies a sample's fields into a pre-allocated row (no rerun call); the
rows go to rerun in columns later (:mod:`.rerun_send`).
"""

from __future__ import annotations

import math

import numpy as np

from vtolftc.telemetry.samples import TelemetrySample

__all__ = ["RowBuffer"]


class RowBuffer:
    """Rows of logged samples, one wide float buffer; column slices name the fields.

    Parameters
    ----------
    rows
        capacity in rows.
    n_act
        number of actuators (width of the ``cmd`` and ``eff`` fields).
    path_every
        every how many rows a point of the flown path is kept.

    Attributes
    ----------
    t : ndarray of int64
        simulated time of each row [us].
    buf : ndarray
        the rows; fields (``sl`` by name): ``att_ref``, ``att`` [rad], ``pos`` NED [m],
        ``q`` (w, x, y, z), ``virt`` [N, N m], ``cmd``, ``eff`` (normalised), ``misc``
        (altitude, altitude reference [m], airspeed, true airspeed [m/s], mode, armed).
    n : int
        rows in use.
    has_truth : bool
        a sample carried the vehicle's truth (effective actuators, true airspeed).
    path_pts : list of tuple
        points of the flown path not yet taken by the sender, NED [m] (the sender empties
        the list on every send, so it never holds more than a chunk's worth).
    """

    def __init__(self, rows: int, n_act: int, path_every: int) -> None:
        cols: dict[str, int] = {"att_ref": 3, "att": 3, "pos": 3, "q": 4, "virt": 5,
                                "cmd": n_act, "eff": n_act, "misc": 6}
        self.sl: dict[str, slice] = {}
        k = 0
        for name, w in cols.items():
            self.sl[name] = slice(k, k + w)
            k += w
        self.n_act = n_act
        self.n = 0
        self.t = np.zeros(rows, dtype=np.int64)
        self.buf = np.zeros((rows, k))
        self.has_truth = False
        self.path_pts: list[tuple[float, float, float]] = []
        self.path_every = path_every
        self.rows_total = 0

    def copy(self) -> RowBuffer:
        """The ``n`` rows in use and the path points, copied (a send deferred to later steps
        reads these while this buffer fills again)."""
        out = object.__new__(RowBuffer)
        out.__dict__.update(self.__dict__)
        out.t, out.buf = self.t[:self.n].copy(), self.buf[:self.n].copy()
        out.path_pts = list(self.path_pts)
        return out

    def add(self, t: int, sample: TelemetrySample) -> int:
        """Copy ``sample`` (at simulated time ``t`` [us]) into the next row; returns its
        flight mode (as an int). The caller empties the buffer before it overflows."""
        st = sample.status
        nav = sample.nav
        tr = sample.truth
        i = self.n
        row = self.buf[i]
        sl = self.sl
        self.t[i] = t
        row[sl["att_ref"]] = st.attitude_ref_rad
        row[sl["att"]] = st.attitude_rad
        row[sl["virt"]] = st.virtual_command[:5]
        row[sl["cmd"]] = st.actuator_commands
        mode = int(st.mode)
        if tr is not None:
            self.has_truth = True
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
        if self.rows_total % self.path_every == 0:
            self.path_pts.append((float(pos[0]), float(pos[1]), float(pos[2])))
        self.rows_total += 1
        self.n = i + 1
        return mode
