"""Run folder writer: telemetry CSV, events, metrics, run configuration and plots.

:class:`RunFolderWriter` is a :class:`~vtolftc.telemetry.RunObserver`. In the run folder it
writes, as the run goes:

- ``run.json``: the configuration (airframe name and sha256, controller, case, gain-file path
  and sha256, seed, scenario, software versions), at the start;
- ``telemetry.csv``: one row per control step (units in the column names; angles in deg at
  this edge), flushed every 0.5 s of simulated time and at the end, so an interrupted or
  crashed run keeps what was written;
- ``events.log``: one line per event (``t_s kind text``), flushed at once;
- ``metrics.json`` and the plots (PNG, matplotlib Agg) at the end: ``trajectory.png``
  (altitude vs north distance, paper figs 7/10), ``attitude.png`` (attitude vs references),
  ``surfaces.png`` (deflections, figs 8/11), ``rotors.png`` (lift-rotor throttles, figs 9/12),
  ``pushers_airspeed.png``.

Errors while plotting are reported in ``events.log`` and never lose the other files.
"""

from __future__ import annotations

import csv
import datetime as _dt
import json
import platform
from pathlib import Path
from typing import Any

import numpy as np

from vtolftc.base.jsonio import json_safe
from vtolftc.telemetry.plotbuffer import DecimatingBuffer
from vtolftc.telemetry.samples import TelemetrySample

__all__ = ["RunFolderWriter", "default_run_dir"]

_NEEDS_QUOTES = frozenset(',"\r\n')  # characters csv.writer would quote a field for
_PLOT_COLS = ("t", "n", "alt", "alt_ref", "V", "roll", "pitch", "yaw", "roll_ref", "pitch_ref",
              "yaw_ref", "mode")  # then one column per actuator command


def actuator_names_of(info: dict[str, Any]) -> tuple[str, ...]:
    """The actuator names of a run whose ``info`` names none: those of its airframe
    (``airframe_obj``, else the file ``airframe_path``, else the shipped default airframe)."""
    af = info.get("airframe_obj")
    if af is None:
        from vtolftc.airframe.loader import load_airframe

        af = load_airframe(info.get("airframe_path"))
    return tuple(af.actuator_names)


def default_run_dir(case: str, controller: str, root: str | Path = "runs") -> Path:
    """``runs/<case>-<controller>-<UTC timestamp>`` (not created)."""
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%S.%fZ")
    return Path(root) / f"case{case}-{controller}-{stamp}"


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    import importlib.metadata as md

    for pkg in ("vtol-ftc", "numpy", "scipy", "osqp", "numba"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = "unknown"
    return out


class RunFolderWriter:
    """Writes a run folder (see the module docstring). ``plots=False`` skips the PNGs."""

    def __init__(self, run_dir: str | Path, *, plots: bool = True,
                 extra_config: dict[str, Any] | None = None) -> None:
        self.run_dir = Path(run_dir)
        self.plots = plots
        self.extra_config = extra_config or {}
        self._csv_file: Any = None
        self._csv: Any = None
        self._events: Any = None
        self._names: list[str] = []
        self._rows = 0
        self._last_flush_usec = 0
        self._plot: DecimatingBuffer | None = None
        """Rows for the end-of-run plots (``plots=True`` only): a fixed-size, evenly
        decimated table, so that a run of any length holds a bounded amount of memory."""
        self._row_fmt = ""
        self._row_fmt_truth = ""
        self.info: dict[str, Any] = {}
        self.finished = False

    # -- observer protocol --------------------------------------------------------------------
    def on_start(self, info: dict[str, Any]) -> None:
        """Create the run folder, write ``run.json``, open ``telemetry.csv`` and ``events.log``."""
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.info = dict(info)
        self._names = list(info.get("actuator_names") or actuator_names_of(info))
        cfg = {**info, **self.extra_config, "seed": info.get("seed", 0),
               "versions": _versions(), "run_dir": str(self.run_dir),
               "started_utc": _dt.datetime.now(_dt.UTC).isoformat()}
        (self.run_dir / "run.json").write_text(json.dumps(json_safe(cfg), indent=2) + "\n",
                                               encoding="utf-8")
        self._events = open(self.run_dir / "events.log", "w", encoding="utf-8")  # noqa: SIM115
        self._csv_file = open(self.run_dir / "telemetry.csv", "w", newline="",  # noqa: SIM115
                              encoding="utf-8")
        self._csv = csv.writer(self._csv_file)
        header = ["time_s", "mode", "armed", "vtol_state", "pos_n_m", "pos_e_m", "pos_d_m",
                  "vel_n_m_s", "vel_e_m_s", "vel_d_m_s", "airspeed_m_s", "altitude_m",
                  "altitude_ref_m", "roll_deg", "pitch_deg", "yaw_deg", "roll_ref_deg",
                  "pitch_ref_deg", "yaw_ref_deg", "p_deg_s", "q_deg_s", "r_deg_s",
                  "fz_cmd_N", "fx_cmd_N", "l_cmd_Nm", "m_cmd_Nm", "n_cmd_Nm"]
        header += [f"u_{n}" for n in self._names]
        header += ["allocation_status", "truth_airspeed_m_s"]
        header += [f"eff_{n}" for n in self._names]
        self._csv.writerow(header)
        self._csv_file.flush()
        n_u = len(self._names)
        common = ("%.3f,%s,%d,%d," + "%.4f," * 3 + "%.3f," * 3 + "%.3f,%.4f,%.3f,"
                  + "%.4f," * 6 + "%.3f," * 3 + "%.4f," * 5 + "%.5f," * n_u + "%s")
        self._row_fmt = common + "," * (1 + n_u) + "\r\n"
        self._row_fmt_truth = common + ",%.3f" + ",%.3f" * n_u + "\r\n"
        if self.plots:
            self._plot = DecimatingBuffer(len(_PLOT_COLS) + n_u)

    def on_sample(self, s: TelemetrySample) -> None:
        """Append one row to ``telemetry.csv`` (angles in deg at this edge), flushed every 0.5 s."""
        if self._csv is None:
            return
        nav, st = s.nav, s.status
        att = np.degrees(st.attitude_rad).tolist()
        ref = np.degrees(st.attitude_ref_rad).tolist()
        w = np.degrees(nav.omega_body_rad_s).tolist()
        t = s.time_usec * 1e-6
        pos = nav.pos_ned_m.tolist()
        h = -pos[2]
        alt_ref = float(st.altitude_ref_m)
        V = float(nav.airspeed_m_s)
        u = st.actuator_commands
        status = st.allocation_status
        if _NEEDS_QUOTES.intersection(status):
            status = '"' + status.replace('"', '""') + '"'
        # one %-format of a template built once (the same text csv.writer wrote field by
        # field with f-strings, at a fraction of the cost)
        vals = (t, st.mode.name, int(st.armed), int(st.vtol_state), *pos,
                *nav.vel_ned_m_s.tolist(), V, h, alt_ref, *att, *ref, *w,
                *np.asarray(st.virtual_command, dtype=float).tolist(),
                *np.asarray(u, dtype=float).tolist(), status)
        if s.truth is not None:
            line = self._row_fmt_truth % (*vals, float(s.truth.airspeed_m_s),
                                          *np.asarray(s.truth.effectiveness,
                                                      dtype=float).tolist())
        else:
            line = self._row_fmt % vals
        self._csv_file.write(line)
        self._rows += 1
        if self._plot is not None:
            self._plot.add((t, pos[0], h, alt_ref, V, *att, *ref, float(int(st.mode)),
                            *np.asarray(u, dtype=float).tolist()))
        if s.time_usec - self._last_flush_usec >= 500_000:  # a crash loses < 0.5 s
            self._csv_file.flush()
            self._last_flush_usec = s.time_usec

    def on_event(self, time_usec: int, kind: str, text: str) -> None:
        """Append ``t_s kind text`` to ``events.log`` and flush it."""
        if self._events is None:
            return
        self._events.write(f"{time_usec * 1e-6:10.3f} {kind:9s} {text}\n")
        self._events.flush()

    def on_finish(self, metrics: dict[str, Any]) -> None:
        """Close the CSV, write ``metrics.json`` and the plots (once; plot errors go to the log)."""
        if self.finished:
            return
        self.finished = True
        try:
            if self._csv_file is not None:
                self._csv_file.flush()
                self._csv_file.close()
            (self.run_dir / "metrics.json").write_text(
                json.dumps(json_safe(metrics), indent=2) + "\n", encoding="utf-8")
            if self.plots and self._rows:
                try:
                    self.write_plots()
                except Exception as exc:  # plots are a convenience: never lose the rest
                    if self._events is not None:
                        self._events.write(f"plotting failed: {exc!r}\n")
        finally:
            if self._events is not None:
                self._events.close()
                self._events = None

    # -- plots ---------------------------------------------------------------------------------
    def write_plots(self) -> None:
        """The paper-like figures from the collected samples."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        if self._plot is None:
            return
        rows = self._plot.rows()
        c = {k: rows[:, i] for i, k in enumerate(_PLOT_COLS)}
        t = c["t"]
        title = (f"{self.info.get('airframe', '')} case {self.info.get('case', '?')}, "
                 f"{self.info.get('controller', '?')}")
        fig, ax = plt.subplots(figsize=(7, 3.5))
        ax.plot(c["n"], c["alt"], label="altitude")
        ax.plot(c["n"], c["alt_ref"], "--", label="reference")
        ax.set_xlabel("north distance (m)")
        ax.set_ylabel("altitude (m)")
        ax.set_title(f"Longitudinal trajectory: {title}")
        ax.grid(True)
        ax.legend()
        fig.tight_layout()
        fig.savefig(self.run_dir / "trajectory.png", dpi=110)
        plt.close(fig)

        fig, axs = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
        for a, k in zip(axs, ("roll", "pitch", "yaw"), strict=True):
            a.plot(t, c[k], label=k)
            a.plot(t, c[f"{k}_ref"], "--", label="reference")
            a.set_ylabel(f"{k} (deg)")
            a.grid(True)
            a.legend(loc="upper right")
        axs[-1].set_xlabel("time (s)")
        axs[0].set_title(f"Attitude: {title}")
        fig.tight_layout()
        fig.savefig(self.run_dir / "attitude.png", dpi=110)
        plt.close(fig)

        u = rows[:, len(_PLOT_COLS):]
        names = self._names
        n_rot = sum(1 for n in names if n.startswith("rotor_"))
        i_push = [i for i, n in enumerate(names) if n.startswith("pusher_")]
        i_surf = [i for i, n in enumerate(names)
                  if not n.startswith("rotor_") and not n.startswith("pusher_")]
        defl = float(self.info.get("max_deflection_deg", 25.0))
        fig, ax = plt.subplots(figsize=(8, 4))
        for i in i_surf:
            ax.plot(t, u[:, i] * defl, label=names[i])
        ax.set_xlabel("time (s)")
        ax.set_ylabel("deflection command (deg)")
        ax.set_title(f"Control surfaces: {title}")
        ax.grid(True)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(self.run_dir / "surfaces.png", dpi=110)
        plt.close(fig)

        fig, axs = plt.subplots(4, 2, figsize=(9, 8), sharex=True, sharey=True)
        for i in range(min(n_rot, 8)):
            a = axs.flat[i]
            a.plot(t, 100.0 * u[:, i])
            a.set_title(names[i], fontsize=9)
            a.grid(True)
        for a in axs[-1]:
            a.set_xlabel("time (s)")
        for a in axs[:, 0]:
            a.set_ylabel("throttle (%)")
        fig.suptitle(f"Lift rotors: {title}")
        fig.tight_layout()
        fig.savefig(self.run_dir / "rotors.png", dpi=110)
        plt.close(fig)

        fig, axs = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
        for i in i_push:
            axs[0].plot(t, 100.0 * u[:, i], label=names[i])
        axs[0].set_ylabel("pusher throttle (%)")
        axs[0].legend()
        axs[0].grid(True)
        axs[1].plot(t, c["V"])
        axs[1].set_ylabel("airspeed (m/s)")
        axs[1].set_xlabel("time (s)")
        axs[1].grid(True)
        fig.tight_layout()
        fig.savefig(self.run_dir / "pushers_airspeed.png", dpi=110)
        plt.close(fig)
