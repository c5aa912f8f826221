"""Nominal effectiveness B(V) against finite differences of the vehicle's force/moment model,
and the passive-FTC import isolation of the autopilot package."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vtolftc.firmware_sim.autopilot.effectiveness import EffectivenessModel
from vtolftc.firmware_sim.vehicle import dynamics as dyn
from vtolftc.firmware_sim.vehicle.model import Vehicle

AUTOPILOT_DIR = Path(__file__).resolve().parents[1] / "firmware_sim" / "autopilot"


def _fd_effectiveness(af, V: float, h: float = 1e-4) -> np.ndarray:
    """d[Fz, Fx, L, M, N]/d(actuator position) of the vehicle in level flight at airspeed V
    (body velocity along x, alpha = beta = 0), by central differences."""
    veh = Vehicle(af, physics=dyn.AERODYNAMICS | dyn.PROPULSION)
    x = veh.state
    x[0:3] = (0.0, 0.0, -30.0)
    x[3:6] = (V, 0.0, 0.0)
    x[6:10] = (1.0, 0.0, 0.0, 0.0)
    x[10:13] = 0.0
    n_u = af.n_actuators
    base = np.zeros(n_u)
    base[:8] = 0.4
    base[8:10] = 0.3
    out = np.zeros((5, n_u))
    for j in range(n_u):
        fm = []
        for s in (+1.0, -1.0):
            xs = x.copy()
            xs[dyn.N_RIGID:] = base
            xs[dyn.N_RIGID + j] += s * h
            _, f = veh.derivatives(xs, base)
            fm.append(f[[2, 0, 3, 4, 5]])
        out[:, j] = (fm[0] - fm[1]) / (2 * h)
    return out


@pytest.mark.parametrize("V", [0.0, 4.0, 10.0, 13.0, 18.0])
def test_effectiveness_matches_vehicle_finite_differences(ds1, V):
    B = EffectivenessModel(ds1).matrix(V)
    B_fd = _fd_effectiveness(ds1, V)
    scale = np.maximum(np.abs(B_fd).max(axis=1, keepdims=True), 1e-9)
    np.testing.assert_allclose(B / scale, B_fd / scale, atol=1e-6)


def test_effectiveness_structure(ds1):
    m = EffectivenessModel(ds1)
    B0 = m.matrix(0.0)
    # hover: surfaces have no effect, lift rotors lift (negative Fz) with their full thrust
    assert np.all(B0[:, 10:] == 0.0)
    np.testing.assert_allclose(B0[0, :8], -35.0)
    # rotor yaw torques cancel for equal thrust; roll from the lateral stations cancels too
    assert abs(B0[4, :8].sum()) < 1e-9 and abs(B0[2, :8].sum()) < 1e-9
    # surfaces scale with dynamic pressure: B(2V) = 4 B(V) for the surface columns
    np.testing.assert_allclose(m.matrix(18.0)[:, 10:], 4.0 * m.matrix(9.0)[:, 10:])
    # non-finite airspeed counts as hover
    np.testing.assert_array_equal(m.matrix(float("nan")), B0)
    out = np.empty((5, 15))
    assert m.matrix(7.0, out=out) is out


def test_matrix_on_grid_is_cached_and_rounded(ds1):
    m = EffectivenessModel(ds1)
    B1 = m.matrix_on_grid(12.96)
    np.testing.assert_array_equal(B1, m.matrix(13.0))
    assert m.matrix_on_grid(13.04) is B1 and not B1.flags.writeable
    np.testing.assert_array_equal(m.matrix_on_grid(float("nan")), m.matrix(0.0))
