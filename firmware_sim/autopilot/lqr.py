"""Reader of LQR attitude gains (``gains/lqr.json``), format ``vtolftc-lqr-gains/1``.

::

    {
      "format": "vtolftc-lqr-gains/1",
      "controller": "lqr",
      "airframe": {"name": "DS-1", "sha256": "<64 hex digits>"},
      "airspeed_breakpoints_m_s": [0.0, ...],      # one or more, strictly increasing
      "axes": {
        "roll":  {"k_int": [...], "k_angle": [...], "k_rate": [...]},
        "pitch": {...},
        "yaw":   {...}
      },
      ... any other top-level keys: free metadata (weights Q, R, design notes)
    }

Per axis, with ``e = angle_ref - angle`` (yaw error wrapped to (-pi, pi])::

    tau = k_int * integral(e dt) + k_angle * e - k_rate * rate      [N m]

units: ``k_int`` N m/(rad s), ``k_angle`` N m/rad, ``k_rate`` N m s/rad. Gains are finite and
>= 0, one value per breakpoint; interpolated piecewise-linearly in airspeed, clamped outside
(exactly as the P-PID schedule). Every validation failure raises :class:`LQRGainsError` (a
``ValueError``) naming the field, the value and what was expected; from a file the message
starts with the file name.
"""

from __future__ import annotations

import bisect
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from os import PathLike
from typing import Any

from vtolftc.firmware_sim.autopilot.schedule import load_document
from vtolftc.rotation import ATTITUDE_AXES as AXES

__all__ = ["FORMAT", "LQR_FIELDS", "LQRAxisGains", "LQRGains", "LQRGainsError"]

FORMAT = "vtolftc-lqr-gains/1"
LQR_FIELDS: tuple[str, ...] = ("k_int", "k_angle", "k_rate")
_SHA256 = re.compile(r"^[0-9a-fA-F]{64}$")


class LQRGainsError(ValueError):
    """Invalid LQR gain data."""


@dataclass(frozen=True, slots=True)
class LQRAxisGains:
    """Gains of one axis: ``k_int`` [N m/(rad s)], ``k_angle`` [N m/rad], ``k_rate``
    [N m s/rad]."""

    k_int: float
    k_angle: float
    k_rate: float


def _num(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def _fmt(x: Any) -> str:
    s = repr(x)
    return s if len(s) <= 60 else s[:57] + "..."


class LQRGains:
    """Validated LQR gains over airspeed; ``gains_at(V)`` -> ``{axis: LQRAxisGains}``."""

    def __init__(self, controller: str, airframe_name: str, airframe_sha256: str,
                 breakpoints_m_s: tuple[float, ...],
                 table: dict[str, dict[str, tuple[float, ...]]],
                 metadata: dict[str, Any] | None = None) -> None:
        self.controller = controller
        self.airframe_name = airframe_name
        self.airframe_sha256 = airframe_sha256.lower()
        self.breakpoints_m_s = tuple(float(b) for b in breakpoints_m_s)
        self.table = table
        self.metadata = metadata or {}
        self._bp = list(self.breakpoints_m_s)
        self._rows = [
            {ax: LQRAxisGains(*(table[ax][f][i] for f in LQR_FIELDS)) for ax in AXES}
            for i in range(len(self._bp))
        ]

    @classmethod
    def load(cls, path: str | PathLike[str]) -> LQRGains:
        """Read and validate an LQR gain file (``vtolftc-lqr-gains/1``); raises
        :class:`LQRGainsError` naming the field that is wrong."""
        return load_document(path, LQRGainsError, "LQR gains", cls.from_dict)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> LQRGains:
        """Validate an already parsed gain document (see :meth:`load`)."""
        if not isinstance(d, Mapping):
            raise LQRGainsError(f"top level: expected a JSON object, got {type(d).__name__}")
        fmt = d.get("format")
        if fmt != FORMAT:
            raise LQRGainsError(f"format: got {_fmt(fmt)}; expected {FORMAT!r}")
        controller = d.get("controller")
        if not isinstance(controller, str) or not controller.strip():
            raise LQRGainsError(f"controller: expected a non-empty string, got {_fmt(controller)}")
        af = d.get("airframe")
        if not isinstance(af, Mapping):
            raise LQRGainsError(f"airframe: expected an object with 'name' and 'sha256', "
                                f"got {_fmt(af)}")
        name = af.get("name")
        if not isinstance(name, str) or not name.strip():
            raise LQRGainsError(f"airframe.name: expected a non-empty string, got {_fmt(name)}")
        sha = af.get("sha256")
        if not isinstance(sha, str) or not _SHA256.match(sha):
            raise LQRGainsError(f"airframe.sha256: expected 64 hexadecimal digits, "
                                f"got {_fmt(sha)}")
        bp = d.get("airspeed_breakpoints_m_s")
        if not isinstance(bp, list) or not bp:
            raise LQRGainsError("airspeed_breakpoints_m_s: expected a non-empty list of "
                                f"airspeeds [m/s], got {_fmt(bp)}")
        for i, b in enumerate(bp):
            if not _num(b):
                raise LQRGainsError(f"airspeed_breakpoints_m_s[{i}]: expected a finite number "
                                    f"[m/s], got {_fmt(b)}")
            if i and not b > bp[i - 1]:
                raise LQRGainsError(f"airspeed_breakpoints_m_s[{i}]: breakpoints must be "
                                    f"strictly increasing, got {b} after {bp[i - 1]}")
        n = len(bp)
        axes = d.get("axes")
        if not isinstance(axes, Mapping):
            raise LQRGainsError(f"axes: expected an object with keys {list(AXES)}, "
                                f"got {_fmt(axes)}")
        for ax in AXES:
            if ax not in axes:
                raise LQRGainsError(f"axes.{ax}: missing axis; expected all of {list(AXES)}")
        extra = sorted(set(axes) - set(AXES))
        if extra:
            raise LQRGainsError(f"axes: unknown axis {extra[0]!r}; expected exactly {list(AXES)}")
        table: dict[str, dict[str, tuple[float, ...]]] = {}
        for ax in AXES:
            a = axes[ax]
            if not isinstance(a, Mapping):
                raise LQRGainsError(f"axes.{ax}: expected an object with {list(LQR_FIELDS)}, "
                                    f"got {_fmt(a)}")
            unknown = sorted(set(a) - set(LQR_FIELDS) - {"metadata"})
            if unknown:
                raise LQRGainsError(f"axes.{ax}.{unknown[0]}: unknown field; expected "
                                    f"{list(LQR_FIELDS)} (and optionally 'metadata')")
            table[ax] = {}
            for f in LQR_FIELDS:
                where = f"axes.{ax}.{f}"
                vals = a.get(f)
                if vals is None:
                    raise LQRGainsError(f"{where}: missing gain list")
                if not isinstance(vals, list) or len(vals) != n:
                    raise LQRGainsError(f"{where}: expected a list of {n} numbers (one per "
                                        f"airspeed breakpoint), got {_fmt(vals)}")
                for i, x in enumerate(vals):
                    if not _num(x):
                        raise LQRGainsError(f"{where}[{i}]: expected a finite number, "
                                            f"got {_fmt(x)}")
                    if x < 0:
                        raise LQRGainsError(f"{where}[{i}]: negative gain {x}; gains must "
                                            "be >= 0")
                table[ax][f] = tuple(float(x) for x in vals)
        known = {"format", "controller", "airframe", "airspeed_breakpoints_m_s", "axes"}
        meta = {k: v for k, v in d.items() if k not in known}
        return cls(controller, name, sha, tuple(bp), table, meta)

    def verify_airframe(self, name: str | None = None, sha256: str | None = None) -> None:
        """Raise :class:`LQRGainsError` if the gains were designed for another airframe."""
        if name is not None and name != self.airframe_name:
            raise LQRGainsError(f"airframe.name: gains are for {self.airframe_name!r}, "
                                f"not {name!r}")
        if sha256 is not None and sha256.lower() != self.airframe_sha256:
            raise LQRGainsError(f"airframe.sha256: gains were designed for airframe file "
                                f"{self.airframe_sha256}, the loaded one is {sha256.lower()}")

    def gains_at(self, airspeed_m_s: float) -> dict[str, LQRAxisGains]:
        """Gains of the three axes at an airspeed [m/s]: piecewise-linear, clamped outside;
        a non-finite airspeed gives the first breakpoint's."""
        bp = self._bp
        V = airspeed_m_s
        if not bp[0] < V:
            return self._rows[0]
        if bp[-1] <= V:
            return self._rows[-1]
        i = bisect.bisect_right(bp, V) - 1
        w = (V - bp[i]) / (bp[i + 1] - bp[i])
        a, b = self._rows[i], self._rows[i + 1]
        return {ax: LQRAxisGains(a[ax].k_int + w * (b[ax].k_int - a[ax].k_int),
                                 a[ax].k_angle + w * (b[ax].k_angle - a[ax].k_angle),
                                 a[ax].k_rate + w * (b[ax].k_rate - a[ax].k_rate))
                for ax in AXES}
