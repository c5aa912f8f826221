"""Load and validate an airframe TOML file into a typed, immutable :class:`Airframe`.

The file format is documented by the shipped reference airframe ``airframe/ds1.toml``. Every
problem with a file is reported as one :class:`AirframeError` naming the file, the field, the
value found and what was expected; nothing else escapes the loader.

Units: SI throughout; angles are given in degrees in the file (keys ending in ``_deg``) and are
converted to radians here. Body axes FRD, origin at the centre of gravity.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

DS1_PATH = Path(__file__).with_name("ds1.toml")

SURFACE_NAMES: tuple[str, ...] = (
    "aileron_left",
    "aileron_right",
    "elevator",
    "rudder_left",
    "rudder_right",
)


class AirframeError(ValueError):
    """A bad airframe file: the message says which file, which field, and what was expected."""


# --------------------------------------------------------------------------------------------
# Typed, immutable description
# --------------------------------------------------------------------------------------------


def _frozen(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Rotor:
    """One rotor. Thrust acts along ``thrust_axis`` (body unit vector) at ``position_m``.

    ``spin_axis`` is the unit vector of the propeller's angular velocity in body axes, so the
    reaction torque on the airframe is ``-torque_to_thrust_m * T * spin_axis``.
    """

    name: str
    position_m: np.ndarray
    thrust_axis: np.ndarray
    spin_axis: np.ndarray
    max_thrust_N: float
    torque_to_thrust_m: float
    time_constant_s: float
    rate_limit_per_s: float
    zero_thrust_axial_speed_m_s: float


@dataclass(frozen=True)
class Wing:
    """Wing geometry and the constant aerodynamic derivatives (per radian)."""

    area_m2: float
    span_m: float
    chord_m: float
    CL0: float
    CL_alpha: float
    CL_max: float
    stall_rounding_rad: float
    post_stall_blend_per_rad: float
    CL_q: float
    CL_de: float
    CD0: float
    oswald_efficiency: float
    CY_beta: float
    CY_p: float
    CY_r: float
    CY_da: float
    CY_dr: float
    Cl_beta: float
    Cl_r: float
    Cl_da: float
    Cl_dr: float
    Cm0: float
    Cm_de: float
    Cn_p: float
    Cn_da: float
    Cn_dr: float
    moment_angle_linear_rad: float
    moment_angle_saturation_rad: float

    @property
    def aspect_ratio(self) -> float:
        """Wing aspect ratio b^2 / S [-]."""
        return self.span_m**2 / self.area_m2

    @property
    def induced_drag_factor(self) -> float:
        """k in CD = CD0 + k CL^2, k = 1 / (pi e AR)."""
        return 1.0 / (math.pi * self.oswald_efficiency * self.aspect_ratio)


@dataclass(frozen=True)
class DerivativeTables:
    """Airspeed-dependent derivatives tabulated over ``airspeed_m_s`` (strictly increasing)."""

    airspeed_m_s: np.ndarray
    C_lp: np.ndarray
    C_mq: np.ndarray
    C_malpha: np.ndarray
    C_nr: np.ndarray
    C_nbeta: np.ndarray

    def at(self, airspeed_m_s: float) -> dict[str, float]:
        """All five derivatives at one airspeed (linear interpolation, clamped outside)."""
        v = float(airspeed_m_s)
        return {
            name: float(np.interp(v, self.airspeed_m_s, getattr(self, name)))
            for name in ("C_lp", "C_mq", "C_malpha", "C_nr", "C_nbeta")
        }


@dataclass(frozen=True)
class Surfaces:
    """Control surfaces sharing their dynamics: one or two ailerons, the elevator, one or two
    rudders (:data:`SURFACE_NAMES` when two of each; a single one is ``aileron`` /
    ``rudder``, carrying the whole aircraft derivative)."""

    names: tuple[str, ...]
    max_deflection_rad: float
    time_constant_s: float
    rate_limit_rad_s: float


@dataclass(frozen=True)
class LandingGear:
    """Ground contact: spring-damper points in body FRD [m] with stiffness [N/m] and
    damping [N s/m] per point."""

    points_m: np.ndarray  # (n, 3) body FRD
    stiffness_N_m: float
    damping_N_s_m: float
    friction_N_s_m: float
    friction_coefficient: float


CRUISE_OVER_STALL = 1.4
"""Cruise airspeed over the stall speed when the file declares none [-] (the usual 1.3-1.5
band of small fixed-wing aircraft: below the wing's best-range speed, well clear of the stall
in gusts)."""

SPEED_GRID_M_S = 0.5
"""Derived airspeeds are rounded up to this grid [m/s] (rounding up keeps the transition end
at or above the stall speed)."""


def round_up_speed(v_m_s: float) -> float:
    """``v_m_s`` rounded up to :data:`SPEED_GRID_M_S` [m/s] (exact multiples stay)."""
    return math.ceil(v_m_s / SPEED_GRID_M_S - 1e-9) * SPEED_GRID_M_S


@dataclass(frozen=True)
class Airspeeds:
    """The airspeeds that matter [m/s]: stall, end of the transition, cruise.

    Declared in the optional ``[airspeeds]`` section or derived from the wing: stall = the
    wing alone at CL_max carrying the weight, transition end = stall rounded up to
    :data:`SPEED_GRID_M_S`, cruise = :data:`CRUISE_OVER_STALL` x stall rounded up (and at least
    one grid step above the transition end). DS-1: 12.73, 13.0, 18.0 m/s. The one rule of the
    project: the synthesis' design points and the autopilot's ``VT_ARSP_TRANS`` /
    ``FW_AIRSPD_TRIM`` come from here. ``declared`` names the ones the file gave.
    """

    stall_m_s: float
    transition_end_m_s: float
    cruise_m_s: float
    declared: tuple[str, ...] = ()


@dataclass(frozen=True)
class Airframe:
    """A whole airframe. Actuator order everywhere: lift rotors, pushers, then surfaces."""

    name: str
    description: str
    source: str
    sha256: str
    air_density_kg_m3: float
    gravity_m_s2: float
    mass_kg: float
    inertia_kg_m2: np.ndarray  # 3x3, body FRD
    wing: Wing
    derivatives: DerivativeTables
    lift_rotors: tuple[Rotor, ...]
    pushers: tuple[Rotor, ...]
    surfaces: Surfaces
    landing_gear: LandingGear
    actuator_names: tuple[str, ...] = field(default=())
    airspeeds: Airspeeds | None = None

    @property
    def weight_N(self) -> float:
        """Weight m g [N]."""
        return self.mass_kg * self.gravity_m_s2

    @property
    def rotors(self) -> tuple[Rotor, ...]:
        """Lift rotors followed by pushers (the first ``n_rotors`` actuators)."""
        return self.lift_rotors + self.pushers

    @property
    def n_actuators(self) -> int:
        """Number of actuators (lift rotors, pushers, surfaces) in the command order."""
        return len(self.actuator_names)

    def actuator_index(self, name: str) -> int:
        """Index of an actuator by name (``rotor_2b``, ``pusher_left``, ``elevator`` ...)."""
        try:
            return self.actuator_names.index(name)
        except ValueError:
            raise KeyError(
                f"unknown actuator {name!r}; this airframe has: {', '.join(self.actuator_names)}"
            ) from None

    def stall_speed_m_s(self) -> float:
        """Level-flight speed at which the wing alone carries the weight at CL_max."""
        q_s = 0.5 * self.air_density_kg_m3 * self.wing.area_m2 * self.wing.CL_max
        return math.sqrt(self.weight_N / q_s)


# --------------------------------------------------------------------------------------------
# Schema-driven validation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Num:
    """A number field: bounds are inclusive unless ``open_lo``/``open_hi``."""

    unit: str
    lo: float = -math.inf
    hi: float = math.inf
    open_lo: bool = False
    open_hi: bool = False

    def describe(self) -> str:
        lo = "(" if self.open_lo else "["
        hi = ")" if self.open_hi else "]"
        rng = f"in {lo}{self.lo:g}, {self.hi:g}{hi}"
        return f"a number {rng}" + (f" ({self.unit})" if self.unit else "")


_POS = {"lo": 0.0, "open_lo": True}

# A group of identical rotors (lift rotors, pushers) and its [[...rotor]] entries.
_ROTOR_GROUP: dict[str, Any] = {
    "max_thrust_N": _Num("N", **_POS, hi=10000.0),
    "torque_to_thrust_m": _Num("m", 0.0, 0.2),
    "time_constant_s": _Num("s", **_POS, hi=2.0),
    "rate_limit_per_s": _Num("1/s", **_POS, hi=1e4),
    "zero_thrust_axial_speed_m_s": _Num("m/s", **_POS),
    "rotor": "rotors",
}

_SCHEMA: dict[str, dict[str, Any]] = {
    "airframe": {"name": str, "description": str},
    "environment": {
        "air_density_kg_m3": _Num("kg/m^3", 0.5, 1.5),
        "gravity_m_s2": _Num("m/s^2", 9.7, 9.9),
    },
    "mass": {
        "mass_kg": _Num("kg", 0.05, 500.0),
        "Jx_kg_m2": _Num("kg m^2", 1e-5, 1e4),
        "Jy_kg_m2": _Num("kg m^2", 1e-5, 1e4),
        "Jz_kg_m2": _Num("kg m^2", 1e-5, 1e4),
        "Jxz_kg_m2": _Num("kg m^2", -1e3, 1e3),
    },
    "wing": {
        "area_m2": _Num("m^2", **_POS, hi=50.0),
        "span_m": _Num("m", **_POS, hi=50.0),
        "chord_m": _Num("m", **_POS, hi=10.0),
        "CL0": _Num("", -1.0, 2.0),
        "CL_alpha_per_rad": _Num("1/rad", 0.5, 8.0),
        "CL_max": _Num("", 0.3, 3.0),
        "stall_rounding_deg": _Num("deg", **_POS, hi=10.0),
        "post_stall_blend_per_rad": _Num("1/rad", 1.0, 500.0),
        "CL_q": _Num("1/rad", -50.0, 50.0),
        "CL_de_per_rad": _Num("1/rad", -5.0, 5.0),
        "CD0": _Num("", 0.0, 1.0),
        "oswald_efficiency": _Num("", 0.3, 1.0),
        "CY_beta": _Num("1/rad", -10.0, 10.0),
        "CY_p": _Num("1/rad", -10.0, 10.0),
        "CY_r": _Num("1/rad", -10.0, 10.0),
        "CY_da": _Num("1/rad", -10.0, 10.0),
        "CY_dr": _Num("1/rad", -10.0, 10.0),
        "Cl_beta": _Num("1/rad", -10.0, 10.0),
        "Cl_r": _Num("1/rad", -10.0, 10.0),
        "Cl_da": _Num("1/rad", -10.0, 10.0),
        "Cl_dr": _Num("1/rad", -10.0, 10.0),
        "Cm0": _Num("", -1.0, 1.0),
        "Cm_de": _Num("1/rad", -10.0, 10.0),
        "Cn_p": _Num("1/rad", -10.0, 10.0),
        "Cn_da": _Num("1/rad", -10.0, 10.0),
        "Cn_dr": _Num("1/rad", -10.0, 10.0),
        "moment_angle_linear_deg": _Num("deg", 1.0, 45.0),
        "moment_angle_saturation_deg": _Num("deg", 1.0, 90.0),
    },
    "derivatives": {
        "airspeed_m_s": "table_axis",
        "C_lp": "table",
        "C_mq": "table",
        "C_malpha": "table",
        "C_nr": "table",
        "C_nbeta": "table",
    },
    "lift_rotors": _ROTOR_GROUP,
    "pushers": _ROTOR_GROUP,
    "surfaces": {
        "ailerons": _Num("", 1.0, 2.0),
        "rudders": _Num("", 1.0, 2.0),
        "max_deflection_deg": _Num("deg", **_POS, hi=60.0),
        "time_constant_s": _Num("s", **_POS, hi=2.0),
        "rate_limit_deg_s": _Num("deg/s", **_POS, hi=5000.0),
    },
    "landing_gear": {
        "points_m": "points",
        "stiffness_N_m": _Num("N/m", **_POS),
        "damping_N_s_m": _Num("N s/m", 0.0),
        "friction_N_s_m": _Num("N s/m", 0.0),
        "friction_coefficient": _Num("", 0.0, 5.0),
    },
}

_ROTOR_SCHEMA: dict[str, Any] = {
    "name": str,
    "x_m": _Num("m", -20.0, 20.0),
    "y_m": _Num("m", -20.0, 20.0),
    "z_m": _Num("m", -20.0, 20.0),
    "spin": ("cw", "ccw"),
    "axis": "axis",
}
_ROTOR_OPTIONAL = frozenset({"axis"})
_OPTIONAL: dict[str, frozenset[str]] = {"surfaces": frozenset({"ailerons", "rudders"})}
"""Optional keys per section (``[surfaces] ailerons`` / ``rudders``: 1 or 2, default 2)."""

HIL_OUTPUTS = 16
"""Outputs of HIL_ACTUATOR_CONTROLS: an airframe has at most this many actuators."""

MIN_HOVER_THRUST_TO_WEIGHT = 1.2
"""Smallest accepted ratio of the lift rotors' total vertical thrust to the weight [-]."""

MAX_CANT_RAD = math.radians(20.0)
"""Largest accepted angle between a rotor's declared thrust axis and its nominal one [rad]."""

_AIRSPEED_KEYS = ("stall_m_s", "transition_end_m_s", "cruise_m_s")


class _Reader:
    """Walks the parsed TOML against the schema, raising one clear AirframeError."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, value: Any, expected: str) -> AirframeError:
        return AirframeError(
            f"{self.source}: field '{where}' = {value!r}: expected {expected}"
        )

    def check_keys(self, table: Mapping[str, Any], allowed: Mapping[str, Any], where: str,
                   optional: frozenset[str] = frozenset()):
        for key in table:
            if key not in allowed:
                near = ", ".join(sorted(allowed))
                at = f"{where}.{key}" if where else key
                raise AirframeError(
                    f"{self.source}: unknown key '{at}': expected one of: {near}"
                )
        for key in allowed:
            if key not in table and key not in optional:
                at = f"{where}.{key}" if where else key
                raise AirframeError(f"{self.source}: missing field '{at}'")

    def number(self, table: Mapping[str, Any], key: str, spec: _Num, where: str) -> float:
        value = table[key]
        at = f"{where}.{key}"
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(at, value, spec.describe())
        v = float(value)
        if not math.isfinite(v) and not (v == math.inf and spec.hi == math.inf):
            raise self.fail(at, value, spec.describe())
        below = v <= spec.lo if spec.open_lo else v < spec.lo
        above = v >= spec.hi if spec.open_hi else v > spec.hi
        if below or above:
            raise self.fail(at, value, spec.describe())
        return v

    def section(self, doc: Mapping[str, Any], name: str) -> dict[str, Any]:
        table = doc[name]
        if not isinstance(table, dict):
            raise self.fail(name, table, "a table ([section])")
        schema = _SCHEMA[name]
        self.check_keys(table, schema, name, _OPTIONAL.get(name, frozenset()))
        out: dict[str, Any] = {}
        for key, spec in schema.items():
            at = f"{name}.{key}"
            if key not in table:
                continue
            if isinstance(spec, _Num):
                out[key] = self.number(table, key, spec, name)
            elif spec is str:
                if not isinstance(table[key], str) or not table[key].strip():
                    raise self.fail(at, table[key], "a non-empty string")
                out[key] = table[key]
            elif spec in ("table_axis", "table"):
                out[key] = self.float_list(table[key], at)
            elif spec == "points":
                out[key] = self.points(table[key], at)
            elif spec == "rotors":
                out[key] = self.rotors(table[key], at)
        return out

    def float_list(self, value: Any, at: str) -> np.ndarray:
        ok = isinstance(value, list) and len(value) >= 1
        ok = ok and all(isinstance(x, int | float) and not isinstance(x, bool) for x in value)
        if not ok or not all(math.isfinite(float(x)) for x in value):
            raise self.fail(at, value, "a non-empty list of finite numbers")
        return np.array(value, dtype=float)

    def points(self, value: Any, at: str) -> np.ndarray:
        ok = isinstance(value, list) and len(value) >= 3
        ok = ok and all(isinstance(p, list) and len(p) == 3 for p in value)
        if ok:
            try:
                arr = np.array(value, dtype=float)
            except (TypeError, ValueError):
                ok = False
            else:
                ok = bool(np.all(np.isfinite(arr)))
        if not ok:
            raise self.fail(at, value, "a list of at least three [x, y, z] points (m, body FRD)")
        return arr

    def rotors(self, value: Any, at: str) -> list[dict[str, Any]]:
        if not isinstance(value, list) or not value:
            raise self.fail(at, value, "one or more [[...rotor]] tables")
        rotors = []
        seen: set[str] = set()
        for i, entry in enumerate(value):
            where = f"{at}[{i}]"
            if not isinstance(entry, dict):
                raise self.fail(where, entry, "a table with name, x_m, y_m, z_m, spin")
            self.check_keys(entry, _ROTOR_SCHEMA, where, _ROTOR_OPTIONAL)
            r: dict[str, Any] = {}
            for key, spec in _ROTOR_SCHEMA.items():
                if key not in entry:
                    continue
                if spec == "axis":
                    r[key] = self.axis(entry[key], f"{where}.{key}")
                elif isinstance(spec, _Num):
                    r[key] = self.number(entry, key, spec, where)
                elif spec is str:
                    name = entry[key]
                    if not isinstance(name, str) or not _rotor_names_ok(name):
                        raise self.fail(f"{where}.name", name,
                                        "a name made of letters, digits and _ (like '2b')")
                    r[key] = name
                else:
                    if entry[key] not in spec:
                        raise self.fail(f"{where}.{key}", entry[key], f"one of {list(spec)}")
                    r[key] = entry[key]
            if r["name"] in seen:
                raise self.fail(f"{where}.name", r["name"], "a name not used by another rotor")
            seen.add(r["name"])
            rotors.append(r)
        return rotors


    def axis(self, value: Any, at: str) -> np.ndarray:
        ok = isinstance(value, list) and len(value) == 3
        ok = ok and all(isinstance(x, int | float) and not isinstance(x, bool) for x in value)
        arr = np.array(value, dtype=float) if ok else np.zeros(3)
        if not ok or not np.all(np.isfinite(arr)) or np.linalg.norm(arr) < 1e-6:
            raise self.fail(at, value, "a thrust direction [x, y, z] (body FRD, non-zero; "
                            "normalised on load, like PX4's CA_ROTORn_AX/AY/AZ)")
        return arr / np.linalg.norm(arr)

    def airspeeds(self, doc: Mapping[str, Any]) -> dict[str, float]:
        """The optional ``[airspeeds]`` section: declared stall / transition-end / cruise."""
        if "airspeeds" not in doc:
            return {}
        table = doc["airspeeds"]
        if not isinstance(table, dict):
            raise self.fail("airspeeds", table, "a table ([airspeeds])")
        allowed = dict.fromkeys(_AIRSPEED_KEYS, _Num("m/s", **_POS, hi=100.0))
        self.check_keys(table, allowed, "airspeeds", frozenset(_AIRSPEED_KEYS))
        out = {k: self.number(table, k, allowed[k], "airspeeds") for k in table}
        full = {**out}
        return full


def _rotor_names_ok(name: str) -> bool:
    return bool(name) and all(ch.isalnum() or ch == "_" for ch in name)


def load_airframe(path: str | Path | None = None) -> Airframe:
    """Load an airframe TOML file (default: the shipped DS-1) into an :class:`Airframe`.

    Raises :class:`AirframeError` with a message naming the field, the value found and what
    was expected, for any problem: unreadable file, TOML syntax, missing or unknown key, wrong
    type, value outside its physical range, non-increasing airspeed table, table lengths that
    do not match.
    """
    p = DS1_PATH if path is None else Path(path)
    source = str(p)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise AirframeError(f"{source}: cannot read the airframe file ({exc.strerror})") from None
    try:
        doc = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise AirframeError(f"{source}: not a UTF-8 text file") from None
    except tomllib.TOMLDecodeError as exc:
        raise AirframeError(f"{source}: not valid TOML: {exc}") from None
    return airframe_from_dict(doc, source=source, sha256=hashlib.sha256(raw).hexdigest())


def airframe_from_dict(
    doc: Mapping[str, Any], *, source: str = "<airframe>", sha256: str = ""
) -> Airframe:
    """Validate an already-parsed airframe document (same rules as :func:`load_airframe`)."""
    rd = _Reader(source)
    rd.check_keys(doc, {**_SCHEMA, "airspeeds": None}, "", frozenset({"airspeeds"}))
    s = {name: rd.section(doc, name) for name in _SCHEMA}
    declared_speeds = rd.airspeeds(doc)

    mass = s["mass"]
    jx, jy, jz, jxz = mass["Jx_kg_m2"], mass["Jy_kg_m2"], mass["Jz_kg_m2"], mass["Jxz_kg_m2"]
    inertia = np.array([[jx, 0.0, -jxz], [0.0, jy, 0.0], [-jxz, 0.0, jz]])
    eig = np.linalg.eigvalsh(inertia)
    if eig.min() <= 0 or eig[0] + eig[1] < eig[2] * (1 - 1e-12):
        raise rd.fail("mass.Jxz_kg_m2", jxz, "an inertia tensor that is positive definite and "
                      "satisfies the triangle inequality (check Jx, Jy, Jz, Jxz)")

    w = s["wing"]
    if w["CL_max"] <= w["CL0"]:
        raise rd.fail("wing.CL_max", w["CL_max"], f"a value above CL0 = {w['CL0']}")
    if w["moment_angle_saturation_deg"] <= w["moment_angle_linear_deg"]:
        raise rd.fail("wing.moment_angle_saturation_deg", w["moment_angle_saturation_deg"],
                      f"a value above moment_angle_linear_deg = {w['moment_angle_linear_deg']}")
    wing = Wing(
        area_m2=w["area_m2"], span_m=w["span_m"], chord_m=w["chord_m"], CL0=w["CL0"],
        CL_alpha=w["CL_alpha_per_rad"], CL_max=w["CL_max"],
        stall_rounding_rad=math.radians(w["stall_rounding_deg"]),
        post_stall_blend_per_rad=w["post_stall_blend_per_rad"], CL_q=w["CL_q"],
        CL_de=w["CL_de_per_rad"], CD0=w["CD0"], oswald_efficiency=w["oswald_efficiency"],
        CY_beta=w["CY_beta"], CY_p=w["CY_p"], CY_r=w["CY_r"], CY_da=w["CY_da"],
        CY_dr=w["CY_dr"], Cl_beta=w["Cl_beta"], Cl_r=w["Cl_r"], Cl_da=w["Cl_da"],
        Cl_dr=w["Cl_dr"], Cm0=w["Cm0"], Cm_de=w["Cm_de"], Cn_p=w["Cn_p"], Cn_da=w["Cn_da"],
        Cn_dr=w["Cn_dr"],
        moment_angle_linear_rad=math.radians(w["moment_angle_linear_deg"]),
        moment_angle_saturation_rad=math.radians(w["moment_angle_saturation_deg"]),
    )

    d = s["derivatives"]
    axis = d["airspeed_m_s"]
    if axis[0] != 0.0 or np.any(axis < 0):
        raise rd.fail("derivatives.airspeed_m_s", axis.tolist(),
                      "airspeeds >= 0 starting at 0 m/s (hover)")
    if np.any(np.diff(axis) <= 0):
        raise rd.fail("derivatives.airspeed_m_s", axis.tolist(),
                      "strictly increasing airspeeds (m/s)")
    sign_rules = {"C_lp": -1, "C_mq": -1, "C_malpha": -1, "C_nr": -1, "C_nbeta": +1}
    for name, sign in sign_rules.items():
        tab = d[name]
        if tab.shape != axis.shape:
            raise rd.fail(f"derivatives.{name}", tab.tolist(),
                          f"{axis.size} values, one per entry of derivatives.airspeed_m_s")
        if np.any(sign * tab < 0):
            want = "<= 0 (damping/stability)" if sign < 0 else ">= 0 (weathercock stability)"
            raise rd.fail(f"derivatives.{name}", tab.tolist(), f"values {want}")
    tables = DerivativeTables(
        airspeed_m_s=_frozen(axis), **{k: _frozen(d[k]) for k in sign_rules}
    )

    def build_rotors(sec: dict[str, Any], axis_thrust: tuple[float, float, float], prefix: str):
        out = []
        nominal = np.array(axis_thrust)
        for i, r in enumerate(sec["rotor"]):
            # Lift rotors: spin seen from above (looking along +z, down): cw -> +z.
            # Pushers: spin seen from behind (looking along +x, forward): cw -> +x.
            look = np.array([0.0, 0.0, 1.0]) if prefix == "lift_rotors" else np.array(
                [1.0, 0.0, 0.0])
            spin_axis = look if r["spin"] == "cw" else -look
            t_axis = nominal
            if "axis" in r:  # a canted rotor: thrust and spin along the declared axis
                t_axis = r["axis"]
                cant = math.acos(min(1.0, float(t_axis @ nominal)))
                if cant > MAX_CANT_RAD:
                    raise rd.fail(f"{prefix}.rotor[{i}].axis", r["axis"].round(6).tolist(),
                                  f"a thrust axis within {math.degrees(MAX_CANT_RAD):g} deg of "
                                  f"{nominal.tolist()} (a small cant; found "
                                  f"{math.degrees(cant):.1f} deg)")
                spin_axis = t_axis * float(look @ nominal) * (1.0 if r["spin"] == "cw" else -1.0)
            out.append(Rotor(
                name=r["name"], position_m=_frozen([r["x_m"], r["y_m"], r["z_m"]]),
                thrust_axis=_frozen(t_axis), spin_axis=_frozen(spin_axis),
                max_thrust_N=sec["max_thrust_N"], torque_to_thrust_m=sec["torque_to_thrust_m"],
                time_constant_s=sec["time_constant_s"], rate_limit_per_s=sec["rate_limit_per_s"],
                zero_thrust_axial_speed_m_s=sec["zero_thrust_axial_speed_m_s"],
            ))
        return tuple(out)

    lift = build_rotors(s["lift_rotors"], (0.0, 0.0, -1.0), "lift_rotors")
    pushers = build_rotors(s["pushers"], (1.0, 0.0, 0.0), "pushers")
    if len(pushers) > 2:
        raise rd.fail("pushers.rotor", [r.name for r in pushers], "one or two pushers")
    su = s["surfaces"]
    counts = {}
    for key in ("ailerons", "rudders"):
        counts[key] = su.get(key, 2.0)
        if counts[key] not in (1.0, 2.0):
            raise rd.fail(f"surfaces.{key}", counts[key], "1 or 2")
    surface_names = (
        ("aileron_left", "aileron_right") if counts["ailerons"] == 2.0 else ("aileron",)
    ) + ("elevator",) + (
        ("rudder_left", "rudder_right") if counts["rudders"] == 2.0 else ("rudder",))
    surfaces = Surfaces(
        names=surface_names, max_deflection_rad=math.radians(su["max_deflection_deg"]),
        time_constant_s=su["time_constant_s"],
        rate_limit_rad_s=math.radians(su["rate_limit_deg_s"]),
    )
    g = s["landing_gear"]
    gear = LandingGear(
        points_m=_frozen(g["points_m"]), stiffness_N_m=g["stiffness_N_m"],
        damping_N_s_m=g["damping_N_s_m"], friction_N_s_m=g["friction_N_s_m"],
        friction_coefficient=g["friction_coefficient"],
    )
    names = (
        tuple(f"rotor_{r.name}" for r in lift)
        + tuple(f"pusher_{r.name}" for r in pushers)
        + surface_names
    )
    if len(set(names)) != len(names):
        raise AirframeError(f"{source}: actuator names are not unique: {names}")
    if len(names) > HIL_OUTPUTS:
        raise rd.fail("lift_rotors.rotor", f"{len(lift)} lift rotors",
                      f"at most {HIL_OUTPUTS} actuators in all (HIL_ACTUATOR_CONTROLS has "
                      f"{HIL_OUTPUTS} outputs; this file has {len(names)})")
    af = Airframe(
        name=s["airframe"]["name"], description=s["airframe"]["description"], source=source,
        sha256=sha256, air_density_kg_m3=s["environment"]["air_density_kg_m3"],
        gravity_m_s2=s["environment"]["gravity_m_s2"], mass_kg=mass["mass_kg"],
        inertia_kg_m2=_frozen(inertia), wing=wing, derivatives=tables, lift_rotors=lift,
        pushers=pushers, surfaces=surfaces, landing_gear=gear, actuator_names=names,
    )
    hover_thrust = sum(r.max_thrust_N * -float(r.thrust_axis[2]) for r in lift)
    if hover_thrust < MIN_HOVER_THRUST_TO_WEIGHT * af.weight_N:
        raise rd.fail("lift_rotors.max_thrust_N", s["lift_rotors"]["max_thrust_N"],
                      f"lift rotors whose vertical thrust is at least "
                      f"{MIN_HOVER_THRUST_TO_WEIGHT:g} x the weight ({af.weight_N:.1f} N): "
                      f"thrust-to-weight {hover_thrust / af.weight_N:.2f}")
    reason = hover_authority_problem(af)
    if reason:
        raise rd.fail("lift_rotors.rotor", [r.name for r in lift], reason)
    return _with_airspeeds(af, declared_speeds, rd)


def hover_effectiveness(af: Airframe) -> np.ndarray:
    """Hover effectiveness of the lift rotors: rows (-Fz, Mx, My, Mz) per newton of thrust.

    Column ``j`` is the upward force [N] and the body moments [N m] (FRD, about the CG) of
    one newton of thrust of lift rotor ``j``: ``r x (T a) - k T s`` with ``a`` its thrust axis,
    ``s`` its spin axis and ``k`` its torque-to-thrust ratio [m].
    """
    cols = []
    for r in af.lift_rotors:
        m = np.cross(r.position_m, r.thrust_axis) - r.torque_to_thrust_m * r.spin_axis
        cols.append([-float(r.thrust_axis[2]), *m.tolist()])
    return np.array(cols).T


def hover_authority_problem(af: Airframe) -> str:
    """Why the lift rotors cannot control the airframe in hover, or ``""`` when they can.

    Rank check: the 4 x n hover effectiveness (:func:`hover_effectiveness`) must have rank 4
    (thrust, roll, pitch and yaw independent). Sign check: the yaw row must have entries of
    both signs (rotors that can only push yaw one way leave it uncontrollable at zero thrust
    change), and so must the roll and pitch rows.
    """
    B = hover_effectiveness(af)
    scale = np.maximum(np.max(np.abs(B), axis=1, keepdims=True), 1e-12)
    Bn = B / scale
    for row, axis_name in ((3, "yaw"), (1, "roll"), (2, "pitch")):
        if not (np.any(Bn[row] > 1e-6) and np.any(Bn[row] < -1e-6)):
            return (f"lift rotors that can turn the airframe both ways in {axis_name} in hover "
                    f"(no {axis_name} authority in hover: check spin directions, positions "
                    f"and cant)")
    if np.linalg.matrix_rank(Bn, tol=1e-6) < 4:
        return ("lift rotors whose thrust, roll, pitch and yaw effects are independent "
                "(hover effectiveness of rank < 4: no yaw authority in hover; check spin "
                "directions and cant)")
    return ""


def _speeds(af: Airframe, declared: Mapping[str, float]) -> tuple[float, float, float]:
    stall = declared.get("stall_m_s", af.stall_speed_m_s())
    end = declared.get("transition_end_m_s", round_up_speed(stall))
    cruise = declared.get("cruise_m_s", max(round_up_speed(CRUISE_OVER_STALL * stall),
                                            end + SPEED_GRID_M_S))
    return stall, end, cruise


def current_airspeeds(af: Airframe) -> Airspeeds:
    """``af``'s airspeeds by the one rule, from its *current* mass and wing (the declared
    ones kept): the same as :attr:`Airframe.airspeeds` for a loaded airframe, and still right
    for one derived with :func:`dataclasses.replace` (a heavier copy stalls faster)."""
    own = af.airspeeds
    names = own.declared if own is not None else ()
    declared = {k: getattr(own, k) for k in names}
    return Airspeeds(*_speeds(af, declared), tuple(sorted(declared)))


def _with_airspeeds(af: Airframe, declared: Mapping[str, float], rd: _Reader) -> Airframe:
    """The airframe with its stall / transition-end / cruise airspeeds, declared or derived."""
    stall, end, cruise = _speeds(af, declared)
    if not stall <= end <= cruise:
        bad = "transition_end_m_s" if end < stall else "cruise_m_s"
        raise rd.fail(f"airspeeds.{bad}", declared.get(bad, end if end < stall else cruise),
                      f"stall <= transition end <= cruise (here {stall:.2f}, {end:.2f}, "
                      f"{cruise:.2f} m/s)")
    return replace(af, airspeeds=Airspeeds(stall, end, cruise, tuple(sorted(declared))))

