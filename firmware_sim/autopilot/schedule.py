"""Airspeed gain schedule of the attitude P-PID loops: reader, validator and interpolator.

The synthesis tool writes the schedule as JSON; the autopilot reads it with this module and
never imports the synthesis code. This docstring is the format's specification.

Format ``vtolftc-gain-schedule/1``
----------------------------------
A JSON object::

    {
      "format": "vtolftc-gain-schedule/1",
      "controller": "gs-shif",
      "airframe": {"name": "DS-1", "sha256": "<64 hex digits>"},
      "airspeed_breakpoints_m_s": [0, 1, 4, 7, 10, 13],
      "axes": {
        "roll":  {"kp_angle": [...], "kp_rate": [...], "ki_rate": [...],
                  "kd_rate": [...], "tf_rate_s": [...], "metadata": {...}},
        "pitch": {...},
        "yaw":   {...}
      },
      ... any other top-level keys: free metadata (achieved norms, mu values, weights, ...)
    }

Fields (all required unless said otherwise):

- ``format``: exactly ``"vtolftc-gain-schedule/1"``. A later incompatible change bumps the
  number; readers reject versions they do not know.
- ``controller``: non-empty string naming the design (e.g. ``"gs-shif"``, ``"shif"``,
  ``"lqr-equivalent"``).
- ``airframe``: object with ``name`` (non-empty string) and ``sha256`` (64 hexadecimal
  digits, the SHA-256 of the airframe file the schedule was designed for; see
  ``GainSchedule.verify_airframe``). Other keys in it are allowed.
- ``airspeed_breakpoints_m_s``: non-empty list of finite numbers [m/s], strictly increasing.
  One breakpoint means a constant-gain controller (e.g. SHIF).
- ``axes``: object with exactly the keys ``roll``, ``pitch``, ``yaw``. Each is an object with
  exactly the five gain lists below, each as long as the breakpoint list, plus an optional
  ``metadata`` value (anything). Gains are finite numbers >= 0; ``tf_rate_s`` must be > 0
  wherever ``kd_rate`` > 0 (a proper derivative filter).

Gains and units (SI; see ``vtolftc.firmware_sim.autopilot.pid``): the inner loop maps the body-rate
error [rad/s] to a moment [N m] about the FRD body axis of that channel::

    rate_ref = kp_angle (angle_ref - angle)                      kp_angle  [1/s]
    tau      = (kp_rate + ki_rate/s + kd_rate s/(tf_rate_s s + 1)) (rate_ref - rate)
                                kp_rate [N m s/rad], ki_rate [N m/rad],
                                kd_rate [N m s²/rad], tf_rate_s [s]

Interpolation: every gain is interpolated piecewise-linearly in airspeed between adjacent
breakpoints (the paper's gain scheduling), clamped outside the breakpoint range (no
extrapolation). A non-finite airspeed gives the gains of the first breakpoint.

Every validation failure raises ``GainScheduleError`` (a ``ValueError``) naming the field
(e.g. ``axes.roll.ki_rate[2]``), the offending value and what was expected; when loading from
a file the message starts with the file name.
"""

from __future__ import annotations

import bisect
import json
import math
import re
from collections.abc import Callable, Mapping
from os import PathLike
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from vtolftc.base.rotation import ATTITUDE_AXES as AXES
from vtolftc.firmware_sim.autopilot.pid import PPIDGains

__all__ = [
    "FORMAT",
    "GAIN_FIELDS",
    "GainSchedule",
    "GainScheduleError",
]

FORMAT = "vtolftc-gain-schedule/1"
GAIN_FIELDS: tuple[str, ...] = ("kp_angle", "kp_rate", "ki_rate", "kd_rate", "tf_rate_s")
_FORMAT_PREFIX = "vtolftc-gain-schedule/"
_SHA256 = re.compile(r"^[0-9a-fA-F]{64}$")


class GainScheduleError(ValueError):
    """Invalid gain-schedule data (message names the field, the value and the expectation)."""


def read_json_file(path: str | PathLike[str], error: type[ValueError], what: str) -> Any:
    """Decode the JSON file ``path``; an unreadable file or invalid JSON raises ``error``
    with a message starting with the file name (``what`` names the content, e.g.
    "gain schedule")."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise error(f"{p}: cannot read {what}: {exc}") from exc
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{p}: not valid JSON: {exc}") from exc


T = TypeVar("T")


def load_document(path: str | PathLike[str], error: type[ValueError], what: str,
                  parse: Callable[[Any], T]) -> T:
    """Read the JSON file ``path`` and validate it with ``parse`` (a ``from_dict``); any
    ``error`` raised names the file first (see :func:`read_json_file`)."""
    data = read_json_file(path, error, what)
    try:
        return parse(data)
    except error as exc:
        raise error(f"{Path(path)}: {exc}") from None


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _fmt(x: Any) -> str:
    s = repr(x)
    return s if len(s) <= 60 else s[:57] + "..."


class GainSchedule:
    """A validated P-PID gain schedule over airspeed.

    Build with ``GainSchedule.load(path)`` or ``GainSchedule.from_dict(d)``; query with
    ``gains_at(airspeed_m_s)``.

    Attributes
    ----------
    controller
        design name from the file.
    airframe_name, airframe_sha256
        airframe the schedule was designed for.
    breakpoints_m_s
        airspeed breakpoints [m/s] (tuple, strictly increasing).
    table
        ``{axis: {gain: tuple of values per breakpoint}}``.
    metadata
        the top-level keys that are not part of the schema, plus per-axis
        ``metadata`` under ``metadata["axes_metadata"][axis]`` when present.
    """

    def __init__(
        self,
        controller: str,
        airframe_name: str,
        airframe_sha256: str,
        breakpoints_m_s: tuple[float, ...],
        table: dict[str, dict[str, tuple[float, ...]]],
        metadata: dict[str, Any] | None = None,
    ) -> None:
        self.controller = controller
        self.airframe_name = airframe_name
        self.airframe_sha256 = airframe_sha256.lower()
        self.breakpoints_m_s = tuple(float(b) for b in breakpoints_m_s)
        self.table = table
        self.metadata = metadata or {}
        # Precomputed rows: one flat tuple of 15 gains (axis-major) per breakpoint.
        n = len(self.breakpoints_m_s)
        self._rows = [tuple(table[ax][f][i] for ax in AXES for f in GAIN_FIELDS) for i in range(n)]
        self._slopes = [
            tuple(b - a for a, b in zip(self._rows[i], self._rows[i + 1], strict=True))
            for i in range(n - 1)
        ]
        self._at_bp = [self._row_to_gains(r) for r in self._rows]
        self._bp = list(self.breakpoints_m_s)
        # the same rows and slopes as float arrays, for control_kernels.scheduled_gains
        self.kernel_tables: tuple[np.ndarray, np.ndarray, np.ndarray] = _kernel_tables(
            self._bp, self._rows, self._slopes)
        #: ``kernel_tables`` concatenated into one read-only array (breakpoints, rows,
        #: slopes: ``control_kernels.scheduled_ppid3_step_packed``'s ``tab``)
        self.kernel_packed: np.ndarray = np.concatenate([a.ravel() for a in self.kernel_tables])
        self.kernel_packed.setflags(write=False)

    # -------------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | PathLike[str]) -> GainSchedule:
        """Read and validate a schedule file (JSON)."""
        return load_document(path, GainScheduleError, "gain schedule", cls.from_dict)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GainSchedule:
        """Validate a decoded schedule (see the module docstring for the schema)."""
        if not isinstance(d, Mapping):
            raise GainScheduleError(f"top level: expected a JSON object, got {type(d).__name__}")
        _check_format(d.get("format"))
        controller = d.get("controller")
        if not isinstance(controller, str) or not controller.strip():
            raise GainScheduleError(
                f"controller: expected a non-empty string, got {_fmt(controller)}"
            )
        af = d.get("airframe")
        af_name, af_sha = _check_airframe(af)
        bp = _check_breakpoints(d.get("airspeed_breakpoints_m_s"))
        table, axes_meta = _check_axes(d.get("axes"), len(bp))

        known = {"format", "controller", "airframe", "airspeed_breakpoints_m_s", "axes"}
        metadata = {k: v for k, v in d.items() if k not in known}
        if axes_meta:
            metadata["axes_metadata"] = axes_meta
        extra_af = {k: v for k, v in af.items() if k not in ("name", "sha256")}
        if extra_af:
            metadata["airframe_extra"] = extra_af
        return cls(controller, af_name, af_sha, tuple(bp), table, metadata)

    def to_dict(self) -> dict[str, Any]:
        """The schedule as a format-1 dict (round-trips through ``from_dict``)."""
        meta = dict(self.metadata)
        axes_meta = meta.pop("axes_metadata", {})
        af_extra = meta.pop("airframe_extra", {})
        axes: dict[str, Any] = {}
        for ax in AXES:
            axes[ax] = {f: list(self.table[ax][f]) for f in GAIN_FIELDS}
            if ax in axes_meta:
                axes[ax]["metadata"] = axes_meta[ax]
        return {
            "format": FORMAT,
            "controller": self.controller,
            "airframe": {"name": self.airframe_name, "sha256": self.airframe_sha256, **af_extra},
            "airspeed_breakpoints_m_s": list(self.breakpoints_m_s),
            "axes": axes,
            **meta,
        }

    # -------------------------------------------------------------------------------------
    @property
    def is_constant(self) -> bool:
        """True for a single-breakpoint (constant-gain) schedule."""
        return len(self._bp) == 1

    def verify_airframe(self, name: str | None = None, sha256: str | None = None) -> None:
        """Raise ``GainScheduleError`` if the schedule was designed for another airframe."""
        if name is not None and name != self.airframe_name:
            raise GainScheduleError(
                f"airframe.name: schedule is for {self.airframe_name!r}, not {name!r}"
            )
        if sha256 is not None and sha256.lower() != self.airframe_sha256:
            raise GainScheduleError(
                f"airframe.sha256: schedule was designed for airframe file "
                f"{self.airframe_sha256}, the loaded airframe file is {sha256.lower()}"
            )

    @staticmethod
    def _row_to_gains(row: tuple[float, ...] | list[float]) -> dict[str, PPIDGains]:
        return {
            "roll": PPIDGains(row[0], row[1], row[2], row[3], row[4]),
            "pitch": PPIDGains(row[5], row[6], row[7], row[8], row[9]),
            "yaw": PPIDGains(row[10], row[11], row[12], row[13], row[14]),
        }

    def gains_at(self, airspeed_m_s: float) -> dict[str, PPIDGains]:
        """Gains of the three axes at an airspeed [m/s].

        Piecewise-linear between breakpoints, clamped outside (no extrapolation); exactly the
        file's values at a breakpoint; a non-finite airspeed gives the first breakpoint's.
        Pure Python on precomputed rows (a few microseconds, fine at 250 Hz). The returned
        dict is a fresh object, but its ``PPIDGains`` are immutable.
        """
        bp = self._bp
        V = airspeed_m_s
        if not bp[0] < V:  # also NaN
            return dict(self._at_bp[0])
        if bp[-1] <= V:
            return dict(self._at_bp[-1])
        i = bisect.bisect_right(bp, V) - 1
        w = (V - bp[i]) / (bp[i + 1] - bp[i])
        if w == 0.0:
            return dict(self._at_bp[i])
        r = self._rows[i]
        s = self._slopes[i]
        return self._row_to_gains([a + w * b for a, b in zip(r, s, strict=True)])

    def __repr__(self) -> str:
        return (
            f"GainSchedule(controller={self.controller!r}, airframe={self.airframe_name!r}, "
            f"breakpoints_m_s={list(self.breakpoints_m_s)})"
        )


def _kernel_tables(bp: list[float], rows: list[tuple[float, ...]],
                   slopes: list[tuple[float, ...]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(breakpoints (n,), rows (n, 3, 5), slopes (max(n - 1, 1), 3, 5))`` as read-only
    float arrays (axis-major rows, ``GAIN_FIELDS`` columns: the P-PID kernel's layout)."""
    n = len(rows)
    out = (np.array(bp, dtype=float), np.array(rows, dtype=float).reshape(n, 3, 5),
           np.array(slopes if slopes else [rows[0]], dtype=float).reshape(-1, 3, 5))
    for a in out:
        a.setflags(write=False)
    return out


# ---------------------------------------------------------------------------------------------
# Validation helpers of GainSchedule.from_dict (each raises GainScheduleError with the path)
# ---------------------------------------------------------------------------------------------
def _check_format(fmt: Any) -> None:
    """Check the ``format`` field (must equal :data:`FORMAT`)."""
    if fmt is None:
        raise GainScheduleError(f"format: missing; expected {FORMAT!r}")
    if fmt != FORMAT:
        if isinstance(fmt, str) and fmt.startswith(_FORMAT_PREFIX):
            raise GainScheduleError(
                f"format: unsupported version {fmt!r}; this reader knows {FORMAT!r}"
            )
        raise GainScheduleError(f"format: unknown format {_fmt(fmt)}; expected {FORMAT!r}")


def _check_airframe(af: Any) -> tuple[str, str]:
    """Check the ``airframe`` object; returns its (name, sha256)."""
    if not isinstance(af, Mapping):
        raise GainScheduleError(
            f"airframe: expected an object with 'name' and 'sha256', got {_fmt(af)}"
        )
    af_name = af.get("name")
    if not isinstance(af_name, str) or not af_name.strip():
        raise GainScheduleError(
            f"airframe.name: expected a non-empty string, got {_fmt(af_name)}"
        )
    af_sha = af.get("sha256")
    if not isinstance(af_sha, str) or not _SHA256.match(af_sha):
        raise GainScheduleError(
            f"airframe.sha256: expected 64 hexadecimal digits, got {_fmt(af_sha)}"
        )
    return af_name, af_sha


def _check_breakpoints(bp: Any) -> list[Any]:
    """Check ``airspeed_breakpoints_m_s`` (finite, strictly increasing, [m/s]); returns it."""
    if not isinstance(bp, list) or not bp:
        raise GainScheduleError(
            "airspeed_breakpoints_m_s: expected a non-empty list of airspeeds [m/s], "
            f"got {_fmt(bp)}"
        )
    for i, b in enumerate(bp):
        if not _is_number(b) or not math.isfinite(b):
            raise GainScheduleError(
                f"airspeed_breakpoints_m_s[{i}]: expected a finite number [m/s], got {_fmt(b)}"
            )
    for i in range(1, len(bp)):
        if not bp[i] > bp[i - 1]:
            raise GainScheduleError(
                f"airspeed_breakpoints_m_s[{i}]: breakpoints must be strictly increasing, "
                f"got {bp[i]} after {bp[i - 1]}"
            )
    return bp


def _check_axes(axes: Any, n: int) -> tuple[dict[str, dict[str, tuple[float, ...]]],
                                            dict[str, Any]]:
    """Check the ``axes`` object (exactly :data:`AXES`, each with ``n`` gains per field);
    returns the gain table and the per-axis metadata."""
    if not isinstance(axes, Mapping):
        raise GainScheduleError(
            f"axes: expected an object with keys {list(AXES)}, got {_fmt(axes)}"
        )
    for ax in AXES:
        if ax not in axes:
            raise GainScheduleError(f"axes.{ax}: missing axis; expected all of {list(AXES)}")
    extra_axes = sorted(set(axes) - set(AXES))
    if extra_axes:
        raise GainScheduleError(
            f"axes: unknown axis {extra_axes[0]!r}; expected exactly {list(AXES)}"
        )
    table: dict[str, dict[str, tuple[float, ...]]] = {}
    axes_meta: dict[str, Any] = {}
    for ax in AXES:
        a = axes[ax]
        if not isinstance(a, Mapping):
            raise GainScheduleError(
                f"axes.{ax}: expected an object with {list(GAIN_FIELDS)}, got {_fmt(a)}"
            )
        unknown = sorted(set(a) - set(GAIN_FIELDS) - {"metadata"})
        if unknown:
            raise GainScheduleError(
                f"axes.{ax}.{unknown[0]}: unknown field; expected {list(GAIN_FIELDS)} "
                "(and optionally 'metadata')"
            )
        if "metadata" in a:
            axes_meta[ax] = a["metadata"]
        table[ax] = {f: _check_gains(a, f"axes.{ax}.{f}", f, n) for f in GAIN_FIELDS}
        for i in range(n):
            if table[ax]["kd_rate"][i] > 0 and not table[ax]["tf_rate_s"][i] > 0:
                raise GainScheduleError(
                    f"axes.{ax}.tf_rate_s[{i}]: expected > 0 where kd_rate > 0 "
                    f"(kd_rate[{i}] = {table[ax]['kd_rate'][i]}), got "
                    f"{table[ax]['tf_rate_s'][i]}"
                )
    return table, axes_meta


def _check_gains(a: Mapping[str, Any], where: str, f: str, n: int) -> tuple[float, ...]:
    """Check one gain list ``a[f]`` (``n`` finite non-negative numbers); returns it."""
    if f not in a:
        raise GainScheduleError(f"{where}: missing gain list")
    vals = a[f]
    if not isinstance(vals, list):
        raise GainScheduleError(
            f"{where}: expected a list of {n} numbers (one per breakpoint), "
            f"got {_fmt(vals)}"
        )
    if len(vals) != n:
        raise GainScheduleError(
            f"{where}: length mismatch: {len(vals)} values for {n} airspeed breakpoints"
        )
    for i, x in enumerate(vals):
        if not _is_number(x) or not math.isfinite(x):
            raise GainScheduleError(
                f"{where}[{i}]: expected a finite number, got {_fmt(x)}"
            )
        if x < 0:
            raise GainScheduleError(
                f"{where}[{i}]: negative gain {x}; gains must be >= 0"
            )
    return tuple(float(x) for x in vals)
