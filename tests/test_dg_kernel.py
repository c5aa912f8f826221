"""The compiled D-G objective (synthesis/dg_kernel.py) against the numpy reference, finite
differences and the generalised eigenproblem of the LMI; the cheap start bound."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from vtolftc.synthesis import dg_scaling as dgs
from vtolftc.synthesis.mixed_mu import mixed_mu_lower, mixed_mu_upper, mixed_mu_upper_start
from vtolftc.synthesis.mu import Block

STRUCTURES = [
    [Block.real(3), Block.real(1)],                                  # the certificate's
    [Block.real(2), Block.real(1)],
    [Block.real(1), Block.full(2)],                                  # diagonal T, with G
    [Block.full(1), Block.full(2)],                                  # diagonal T, no G
    [Block.real(3), Block.real(1), Block.repeated_complex(3), Block.repeated_complex(1)],
]


def _objectives(blocks: list[Block], seed: int) -> tuple[dgs._DGObjective, dgs._DGObjective,
                                                         np.ndarray]:
    rng = np.random.default_rng(seed)
    st = dgs.BlockStructure(blocks)
    n = st.m_shape[0]
    M = rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n))
    par = dgs._dg_parametrisation(st.blocks)
    x = 0.4 * rng.normal(size=par.n_params)
    return dgs._DGObjective(M, par, True), dgs._DGObjective(M, par, False), x


@pytest.mark.parametrize("k", range(len(STRUCTURES)))
@pytest.mark.parametrize("smooth", [0.0, 1e-3, 3e-2])
def test_compiled_equals_numpy_reference(k: int, smooth: float) -> None:
    a, b, x = _objectives(STRUCTURES[k], k)
    a.smooth = b.smooth = smooth
    fa, ga = a(x)
    fb, gb = b(x)
    assert fa == pytest.approx(fb, rel=1e-12)
    np.testing.assert_allclose(ga, gb, rtol=1e-9, atol=1e-11 * np.max(np.abs(gb)))
    assert a.value(x) == pytest.approx(b.value(x), rel=1e-12)
    assert a.best == pytest.approx(b.best, rel=1e-12)


@pytest.mark.parametrize("k", range(len(STRUCTURES)))
def test_compiled_gradient_is_the_finite_difference(k: int) -> None:
    """The smoothed objective is differentiable: central differences of f."""
    a, _, x = _objectives(STRUCTURES[k], 10 + k)
    a.smooth = 3e-2
    _, g = a(x)
    h = 1e-6
    fd = np.array([(a(x + h * e)[0] - a(x - h * e)[0]) / (2 * h) for e in np.eye(x.size)])
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(fd)))


@pytest.mark.parametrize("k", range(len(STRUCTURES)))
def test_compiled_value_is_the_lmi_eigenvalue(k: int) -> None:
    """lambda_max = the largest generalised eigenvalue of (M^H D M + j(G M - M^H G), D)
    with the (D, G) of the same parameters (scipy, independent of the T-parametrisation)."""
    a, _, x = _objectives(STRUCTURES[k], 20 + k)
    D, G = a.par.matrices(x)
    M = a.M
    H = M.conj().T @ D @ M + 1j * (G @ M - M.conj().T @ G)
    ref = scipy.linalg.eigh(0.5 * (H + H.conj().T), D, eigvals_only=True)[-1]
    assert a.value(x) == pytest.approx(ref, rel=1e-9)


def test_start_bound_is_the_unoptimised_bound() -> None:
    """mixed_mu_upper_start: the D-G bound without iterations, >= the optimised bound >= the
    verified lower bound; D = I alone gives sigma_max(M)."""
    rng = np.random.default_rng(5)
    for blocks in STRUCTURES:
        st = dgs.BlockStructure(blocks)
        n = st.m_shape[0]
        for _ in range(3):
            M = rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n))
            s = mixed_mu_upper_start(M, blocks)
            ref = mixed_mu_upper(M, blocks, method="dg", maxiter=0, target=math.inf).value
            assert s == pytest.approx(ref, rel=1e-13)  # ref is re-checked: last bits
            assert s <= np.linalg.norm(M, 2) * (1 + 1e-12)
            up = mixed_mu_upper(M, blocks, method="dg").value
            assert s >= up * (1 - 1e-12)
            assert up >= mixed_mu_lower(M, blocks, n_starts=1)[0] * (1 - 1e-9)
