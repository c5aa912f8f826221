"""Battery model of the simulated vehicle: a LiPo pack feeding the rotors and pushers.

State of charge ``soc`` (0..1) by coulomb counting; terminal voltage

    V = n_cells * OCV(soc) - I * R_internal

with the open-circuit voltage ``OCV`` of one LiPo cell piecewise linear in ``soc`` (a typical
discharge curve: 3.27 V empty, 3.7 V around 20 %, 4.2 V full) and ``I`` the pack current drawn
by the electric power ``P`` of the propulsion and the avionics: ``P = V I``, solved for ``I``
(the smaller root of ``R I^2 - E I + P = 0``, ``E = n OCV``).

Electric power of one propeller from momentum theory with axial inflow ``V_a`` (0 for the lift
rotors, the airspeed for the pushers)::

    P_ideal = T (V_a / 2 + sqrt(V_a^2 / 4 + T / (2 rho A)))
    P_elec  = P_ideal / (FM * eta_motor)

(``A`` the disk area of the propeller diameter given here, ``FM`` figure of merit, ``eta``
motor and ESC efficiency). The airframe file carries no propeller diameters; the defaults (22"
lift, 16" pushers) are those of a 12.5 kg dual-system VTOL of the DS-1 class: hover then draws
about 1.1 kW (about 50 A from 6S), cruise at 18 m/s about 0.3 kW.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["BatteryModel", "BatterySpec", "cell_ocv", "propeller_power_w"]

_SOC = np.array([0.0, 0.05, 0.1, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0])
_OCV = np.array([3.27, 3.5, 3.61, 3.70, 3.79, 3.87, 4.0, 4.08, 4.2])


def cell_ocv(soc: float) -> float:
    """Open-circuit voltage of one LiPo cell [V] at state of charge ``soc`` (0..1)."""
    return float(np.interp(min(max(soc, 0.0), 1.0), _SOC, _OCV))


def propeller_power_w(thrust_n: float, axial_speed_m_s: float, diameter_m: float,
                      rho: float = 1.225, figure_of_merit: float = 0.7,
                      eta_motor: float = 0.85) -> float:
    """Electric power [W] of a propeller giving ``thrust_n`` with axial inflow (see the module
    docstring); 0 for no thrust."""
    t = max(0.0, float(thrust_n))
    if t == 0.0:
        return 0.0
    area = math.pi * diameter_m * diameter_m / 4.0
    va = max(0.0, float(axial_speed_m_s))
    p_ideal = t * (va / 2.0 + math.sqrt(va * va / 4.0 + t / (2.0 * rho * area)))
    return p_ideal / (figure_of_merit * eta_motor)


@dataclass(frozen=True)
class BatterySpec:
    """A battery pack and the propellers it feeds."""

    cells: int = 6
    capacity_ah: float = 16.0
    r_internal_ohm: float = 0.015
    """Pack internal resistance (cells, wiring, connectors) [ohm]."""
    avionics_w: float = 15.0
    lift_prop_diameter_m: float = 0.56
    pusher_prop_diameter_m: float = 0.41
    initial_soc: float = 1.0


class BatteryModel:
    """Coulomb-counting LiPo pack (see the module docstring)."""

    def __init__(self, spec: BatterySpec | None = None, rho: float = 1.225) -> None:
        self.spec = spec or BatterySpec()
        self.rho = rho
        self.soc = float(self.spec.initial_soc)
        self.current_a = 0.0
        self.power_w = 0.0
        self.consumed_mah = 0.0
        self.voltage_v = self.open_circuit_v()

    def open_circuit_v(self) -> float:
        """Pack open-circuit voltage at the current state of charge (V)."""
        return self.spec.cells * cell_ocv(self.soc)

    def load_power_w(self, lift_thrusts_n: np.ndarray, pusher_thrusts_n: np.ndarray,
                     airspeed_m_s: float) -> float:
        """Electric power [W] of the propulsion at these thrusts, plus the avionics."""
        s = self.spec
        p = s.avionics_w
        for t in np.asarray(lift_thrusts_n, dtype=float).tolist():
            p += propeller_power_w(t, 0.0, s.lift_prop_diameter_m, self.rho)
        for t in np.asarray(pusher_thrusts_n, dtype=float).tolist():
            p += propeller_power_w(t, airspeed_m_s, s.pusher_prop_diameter_m, self.rho)
        return p

    def step(self, dt_s: float, power_w: float) -> None:
        """Draw ``power_w`` for ``dt_s`` seconds."""
        e = self.open_circuit_v()
        r = self.spec.r_internal_ohm
        disc = e * e - 4.0 * r * power_w
        # beyond the pack's maximum power (E^2 / 4R) the voltage collapses to E / 2
        i = (e - math.sqrt(disc)) / (2.0 * r) if disc > 0 else e / (2.0 * r)
        self.current_a = i
        self.power_w = power_w
        self.voltage_v = e - i * r
        dq_ah = i * dt_s / 3600.0
        self.consumed_mah += 1000.0 * dq_ah
        self.soc = max(0.0, self.soc - dq_ah / self.spec.capacity_ah)


def vehicle_power_w(battery: BatteryModel, vehicle: object) -> float:
    """Electric power [W] the vehicle's propulsion draws now: thrust of every lift rotor and
    pusher from its actuator position, maximum thrust and effectiveness (faults: a rotor that
    gives less thrust draws less), pushers with the airspeed as inflow (thrust falling to zero
    at their zero-thrust axial speed, as in the dynamics)."""
    from vtolftc.firmware_sim.vehicle.dynamics import N_RIGID

    af = vehicle.airframe  # type: ignore[attr-defined]
    x = vehicle.x  # type: ignore[attr-defined]
    eff = vehicle.eff  # type: ignore[attr-defined]
    v_air = float(vehicle.fm[6])  # type: ignore[attr-defined]
    n_lift = len(af.lift_rotors)
    lift = [x[N_RIGID + i] * r.max_thrust_N * eff[i] for i, r in enumerate(af.lift_rotors)]
    push = []
    for j, r in enumerate(af.pushers):
        i = n_lift + j
        push.append(x[N_RIGID + i] * r.max_thrust_N * eff[i]
                    * min(1.25, max(0.0, 1.0 - v_air / r.zero_thrust_axial_speed_m_s)))
    return battery.load_power_w(np.array(lift), np.array(push), v_air)
