"""Battery monitoring and the low-battery failsafe, with PX4's parameters.

:class:`BatteryMonitor` turns the vehicle's power-module readings (pack voltage [V] and current
[A], as a BATTERY_STATUS from the simulator) into PX4's battery estimate:

- remaining = the load-compensated voltage estimate at the first reading (``BAT1_V_EMPTY`` ..
  ``BAT1_V_CHARGED`` per cell, the cell voltage raised by ``BAT1_R_INTERNAL * I``), then
  coulomb counting against ``BAT1_CAPACITY`` [mAh];
- warning levels from ``BAT_LOW_THR``, ``BAT_CRIT_THR``, ``BAT_EMERGEN_THR`` (fractions):
  LOW -> a warning; CRITICAL and EMERGENCY -> the action of ``COM_LOW_BAT_ACT`` (0 warning
  only, 2 land, 3 return at critical and land at emergency), each level acted on once.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from vtolftc.firmware_sim.autopilot.interface import ParameterStore, ParamType

__all__ = ["BATTERY_PARAMS", "BatteryMonitor"]

BATTERY_PARAMS: tuple[tuple[str, float, ParamType, float, float, str], ...] = (
    ("BAT1_N_CELLS", 6, ParamType.INT32, 1, 14, "battery cells in series"),
    ("BAT1_CAPACITY", 16000.0, ParamType.REAL32, 100.0, 100000.0, "battery capacity, mAh"),
    ("BAT1_V_EMPTY", 3.5, ParamType.REAL32, 2.5, 4.0, "empty cell voltage, V"),
    ("BAT1_V_CHARGED", 4.05, ParamType.REAL32, 3.5, 4.4, "full cell voltage, V"),
    ("BAT1_R_INTERNAL", 0.015, ParamType.REAL32, 0.0, 0.5,
     "pack internal resistance (load compensation), ohm"),
    ("BAT_LOW_THR", 0.15, ParamType.REAL32, 0.12, 0.5, "low battery level, fraction"),
    ("BAT_CRIT_THR", 0.07, ParamType.REAL32, 0.05, 0.25, "critical battery level, fraction"),
    ("BAT_EMERGEN_THR", 0.05, ParamType.REAL32, 0.03, 0.1,
     "emergency battery level, fraction"),
    ("COM_LOW_BAT_ACT", 0, ParamType.INT32, 0, 3,
     "low-battery action: 0 warning, 2 land, 3 return at critical / land at emergency"),
)

LEVEL_NAMES = ("OK", "LOW", "CRITICAL", "EMERGENCY")
"""MAV_BATTERY_CHARGE_STATE 1..4 minus one."""


class BatteryMonitor:
    """PX4-style battery estimate and low-battery failsafe (see the module docstring).

    Parameters
    ----------
    params
        the autopilot's parameter store (the BAT_* parameters are registered in it).
    on_action
        ``f(action, text)``; ``action`` is "warn", "land" or "rtl".
    """

    def __init__(self, params: ParameterStore,
                 on_action: Callable[[str, str], None] | None = None) -> None:
        for name, default, typ, lo, hi, desc in BATTERY_PARAMS:
            if name not in params:
                params.register(name, default, typ, lo, hi, desc)
        self.params = params
        self.on_action = on_action or (lambda action, text: None)
        self.voltage_v = math.nan
        self.current_a = math.nan
        self.remaining = math.nan
        self.consumed_mah = 0.0
        self.level = 0
        self._soc0 = math.nan
        self._t_usec: int | None = None

    def voltage_estimate(self, voltage_v: float, current_a: float) -> float:
        """Remaining fraction from the load-compensated cell voltage (linear, clipped)."""
        p = self.params
        n = max(1, int(p.get("BAT1_N_CELLS")))
        cell = voltage_v / n + p.get("BAT1_R_INTERNAL") * current_a / n
        lo, hi = p.get("BAT1_V_EMPTY"), p.get("BAT1_V_CHARGED")
        return min(max((cell - lo) / (hi - lo), 0.0), 1.0)

    def update(self, time_usec: int, voltage_v: float, current_a: float) -> None:
        """One power-module reading at simulated ``time_usec``."""
        if not (math.isfinite(voltage_v) and math.isfinite(current_a)):
            return
        if self._t_usec is not None and time_usec > self._t_usec:
            dt = (time_usec - self._t_usec) * 1e-6
            self.consumed_mah += 0.5 * (current_a + self.current_a) * dt / 3.6
        self._t_usec = int(time_usec)
        self.voltage_v, self.current_a = float(voltage_v), float(current_a)
        if not math.isfinite(self._soc0):
            self._soc0 = self.voltage_estimate(voltage_v, current_a)
        cap = self.params.get("BAT1_CAPACITY")
        self.remaining = max(0.0, self._soc0 - self.consumed_mah / cap)
        self._check_levels()

    def _check_levels(self) -> None:
        p = self.params
        r = self.remaining
        level = 3 if r < p.get("BAT_EMERGEN_THR") else 2 if r < p.get("BAT_CRIT_THR") \
            else 1 if r < p.get("BAT_LOW_THR") else 0
        if level <= self.level:
            return
        self.level = level
        act = int(p.get("COM_LOW_BAT_ACT"))
        text = f"battery {LEVEL_NAMES[level].lower()}: {100 * r:.0f} % remaining"
        if level == 1 or act == 0:
            self.on_action("warn", text)
        elif act == 2:
            self.on_action("land", text + ": landing")
        elif act == 3:
            self.on_action("rtl" if level == 2 else "land",
                           text + (": returning" if level == 2 else ": landing"))
        else:
            self.on_action("warn", text)

    @property
    def charge_state(self) -> int:
        """MAV_BATTERY_CHARGE_STATE (0 undefined before the first reading, 1 OK .. 4)."""
        return 0 if not math.isfinite(self.remaining) else self.level + 1
