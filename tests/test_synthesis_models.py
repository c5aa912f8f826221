"""Control-oriented models (paper eq 1-3) and multiplicative uncertainty weights."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from vtolftc.firmware_sim.vehicle.linearize import linearize
from vtolftc.firmware_sim.vehicle.model import Vehicle
from vtolftc.firmware_sim.vehicle.trim import trim_level_flight
from vtolftc.synthesis.models import attitude_model, axis_coefficients, rate_model
from vtolftc.synthesis.uncertainty import (
    PAPER_DESIGN_POINTS,
    UncertaintyWeight,
    cover,
    fit_weight,
    relative_error,
)

AXIS_ROWS = {"roll": ("p", "dphi", "aileron_left"), "pitch": ("q", "dtheta", "elevator"),
             "yaw": ("r", "dpsi", "rudder_left")}


@pytest.mark.parametrize("V", [4.0, 7.0, 10.0, 13.0])
@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
def test_models_match_the_linearised_vehicle(ds1, axis, V):
    """The rotational block of the 6-DOF linearisation (velocity held) has the poles of the
    control-oriented model of the same axis."""
    tp = trim_level_flight(ds1, V, pitch_rad=0.0)
    lm = linearize(Vehicle(ds1), tp.state)
    rate, angle, _ = AXIS_ROWS[axis]
    i_r, i_a = lm.state_names.index(rate), lm.state_names.index(angle)
    A2 = lm.A[np.ix_([i_a, i_r], [i_a, i_r])]
    model = attitude_model(ds1, axis, V)
    assert np.allclose(A2, model.A, rtol=1e-5, atol=1e-8)
    # Every pole of the rate model (eq 1-3) is a pole of the linearised rotational block.
    eig = np.linalg.eigvals(A2)
    for pole in ct.poles(rate_model(ds1, axis, V)):
        assert np.min(np.abs(eig - pole)) < 1e-5 * max(1.0, abs(pole))


def test_gamma_scales_the_gain_and_hover_is_an_inertia(ds1):
    g0 = rate_model(ds1, "pitch", 10.0)
    g6 = rate_model(ds1, "pitch", 10.0, gamma=0.6)
    w = 1j * 3.0
    assert g6(w) / g0(w) == pytest.approx(0.4)
    hover = axis_coefficients(ds1, "yaw", 0.0)
    assert hover.damping == 0.0 and hover.stiffness == 0.0
    assert rate_model(ds1, "roll", 0.0)(1j) == pytest.approx(1 / (1.6j))
    with pytest.raises(ValueError, match="gamma"):
        rate_model(ds1, "roll", 4.0, gamma=1.2)
    with pytest.raises(ValueError, match="axis"):
        axis_coefficients(ds1, "heave", 4.0)


def test_relative_error_at_high_frequency_is_the_effectiveness_loss(ds1):
    rel = relative_error(ds1, "roll", PAPER_DESIGN_POINTS[3], np.array([1e4]))
    assert rel.bound[0] == pytest.approx(0.6, abs=1e-3)


def test_fit_recovers_a_known_first_order_weight():
    om = np.logspace(-2, 3, 200)
    truth = UncertaintyWeight(0.3, (2.0,), (20.0,))
    fit = fit_weight(om, truth.magnitude(om), order=1, margin=1.0)
    assert np.all(fit.magnitude(om) >= truth.magnitude(om) * (1 - 1e-9))
    assert np.max(fit.magnitude(om) / truth.magnitude(om)) < 1.02


@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
def test_weights_bound_the_perturbed_set_and_are_stable_min_phase(ds1, axis):
    om = np.logspace(-4, 4, 3000)
    for pt in PAPER_DESIGN_POINTS:
        W, _ = cover(ds1, axis, pt)
        tf = W.tf()
        assert np.all(np.real(ct.poles(tf)) < 0) and np.all(np.real(ct.zeros(tf)) < 0)
        # An independent, finer sampling of the perturbed set stays under the weight.
        fine = relative_error(ds1, axis, pt, om, n_airspeeds=33, n_gammas=7)
        assert np.all(W.magnitude(om) >= fine.bound), (axis, pt.number)
        # At high frequency the relative error is the largest loss of effectiveness (0.6).
        assert fine.bound[-1] == pytest.approx(0.6, abs=0.02)
