"""Tests of vtolftc.synthesis.hinfnorm (exact H-infinity norm, Hamiltonian two-step algorithm)."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

from vtolftc.synthesis.hinfnorm import (
    HinfNorm,
    frequency_response,
    hinf_norm,
    is_stable,
    sigma_max_response,
)


def _random_systems(count: int, seed: int) -> list[control.StateSpace]:
    rng = np.random.default_rng(seed)
    np.random.seed(seed)  # control.rss draws from numpy's global generator
    systems = []
    while len(systems) < count:
        n = int(rng.integers(1, 13))
        p = int(rng.integers(1, 4))
        m = int(rng.integers(1, 4))
        sys = control.rss(n, p, m)
        if is_stable(sys.A):
            systems.append(sys)
    return systems


@pytest.mark.parametrize("seed", [0, 1])
def test_matches_slycot_ab13dd_on_random_systems(seed: int) -> None:
    for sys in _random_systems(30, seed):
        ref, _ = control.linfnorm(sys)  # slycot ab13dd
        res = hinf_norm(sys)
        assert res.value == pytest.approx(ref, rel=1e-6)
        # the reported peak frequency really attains the norm
        if math.isfinite(res.peak_frequency_rad_s):
            sig = sigma_max_response(sys, np.array([res.peak_frequency_rad_s]))[0]
            assert sig == pytest.approx(res.value, rel=1e-9)


def test_first_order_closed_form() -> None:
    k, a = 3.0, 0.5
    res = hinf_norm(control.tf([k], [1.0, a]))
    assert isinstance(res, HinfNorm)
    assert res.value == pytest.approx(k / a, rel=1e-10)
    assert res.peak_frequency_rad_s == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("zeta", [0.3, 0.05, 0.005])
def test_lightly_damped_resonance(zeta: float) -> None:
    wn = 7.0
    sys = control.tf([wn**2], [1.0, 2 * zeta * wn, wn**2])
    res = hinf_norm(sys)
    peak = 1.0 / (2 * zeta * math.sqrt(1 - zeta**2))
    assert res.value == pytest.approx(peak, rel=1e-9)
    assert res.peak_frequency_rad_s == pytest.approx(wn * math.sqrt(1 - 2 * zeta**2), rel=1e-5)


def test_pure_feedthrough_and_static() -> None:
    D = np.array([[1.0, 2.0], [0.5, -1.0]])
    res = hinf_norm((np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((2, 0)), D))
    assert res.value == pytest.approx(np.linalg.norm(D, 2), rel=1e-12)
    # a stable system whose supremum is only reached at infinite frequency (high-pass)
    res_hp = hinf_norm(control.tf([2.0, 0.0], [1.0, 1.0]))
    assert res_hp.value == pytest.approx(2.0, rel=1e-9)
    assert res_hp.peak_frequency_rad_s == math.inf


def test_nonzero_feedthrough_mimo() -> None:
    rng = np.random.default_rng(3)
    np.random.seed(3)
    sys = control.rss(5, 2, 3)
    sys = control.ss(sys.A, sys.B, sys.C, rng.standard_normal((2, 3)))
    ref, _ = control.linfnorm(sys)
    assert hinf_norm(sys).value == pytest.approx(ref, rel=1e-7)


def test_unstable_is_inf() -> None:
    res = hinf_norm(control.tf([1.0], [1.0, -0.1]))
    assert res.value == math.inf
    assert math.isnan(res.peak_frequency_rad_s)
    # marginally stable (integrator) is treated as unstable as well
    assert hinf_norm(control.tf([1.0], [1.0, 0.0])).value == math.inf


def test_is_stable_and_margin() -> None:
    A = np.diag([-1.0, -0.2])
    assert is_stable(A)
    assert not is_stable(A, margin=0.5)
    assert is_stable(np.zeros((0, 0)))
    with pytest.raises(ValueError, match="square"):
        is_stable(np.zeros((2, 3)))


def test_frequency_response_shape_and_values() -> None:
    sys = control.tf([1.0], [1.0, 1.0])
    w = np.array([0.0, 1.0, 10.0])
    F = frequency_response(sys, w)
    assert F.shape == (3, 1, 1)
    np.testing.assert_allclose(F[:, 0, 0], 1.0 / (1j * w + 1.0), rtol=1e-12)


def test_bad_input_messages() -> None:
    with pytest.raises(ValueError, match="B must have shape"):
        hinf_norm((np.eye(2), np.ones((3, 1)), np.ones((1, 2)), np.zeros((1, 1))))
    with pytest.raises(ValueError, match="continuous-time"):
        hinf_norm(control.tf([1.0], [1.0, 0.5], 0.1))
    with pytest.raises(ValueError, match="4 arrays"):
        hinf_norm((np.eye(2), np.ones((2, 1))))
    with pytest.raises(ValueError, match="rtol"):
        hinf_norm(control.tf([1.0], [1.0, 1.0]), rtol=0.0)
