"""Every mu upper bound comes with scalings that prove it (issue 23, item 6).

Property tests over random M and block structures (real, complex, repeated, full and
non-square blocks): the (D, G) returned by :func:`mixed_mu_upper` and by :func:`mu_bounds`
satisfy the LMI M^H D M + j(G M - M^H G) <= beta^2 D at the returned beta, with D > 0
commuting with the structure and G Hermitian and non-zero only on the real blocks; and the two
functions agree on the upper bound. The check here is written out independently of the code
under test (numpy eigenvalues of the LMI matrix, not :func:`certified_value`).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as hs

from vtolftc.synthesis.dg_scaling import BlockStructure, MixedMuUpper, certified_value
from vtolftc.synthesis.mixed_mu import mixed_mu_bounds, mixed_mu_upper
from vtolftc.synthesis.mu import Block, mu_bounds, mu_upper_bound

_SETTINGS = settings(max_examples=60, deadline=None, derandomize=True,
                     suppress_health_check=[HealthCheck.too_slow])


def _lmi_max(M: np.ndarray, D: np.ndarray, G: np.ndarray | None, beta: float) -> float:
    """Largest eigenvalue of M^H D M + j(G M - M^H G) - beta^2 D (<= 0: the bound holds)."""
    H = M.conj().T @ D @ M - beta**2 * D
    if G is not None:
        H = H + 1j * (G @ M - M.conj().T @ G)
    return float(np.linalg.eigvalsh(0.5 * (H + H.conj().T)).max())


def _tol(M: np.ndarray, D: np.ndarray, beta: float) -> float:
    scale = float(np.linalg.norm(D, 2)) * (beta**2 + float(np.linalg.norm(M, 2)) ** 2)
    return 1e-8 * scale + 1e-300


def _square_blocks(blocks: list[Block]) -> list[Block]:
    """The square-block structure of the zero-padded M (non-square full blocks padded)."""
    return [Block.full(max(b.rows, b.cols)) if b.kind == "full" else b for b in blocks]


def _assert_structured(D: np.ndarray, G: np.ndarray | None, blocks: list[Block]) -> None:
    """D Hermitian > 0 commuting with Delta; G Hermitian, non-zero on the real blocks only."""
    n = D.shape[0]
    np.testing.assert_allclose(D, D.conj().T, atol=1e-10 * np.linalg.norm(D, 2))
    assert np.linalg.eigvalsh(0.5 * (D + D.conj().T)).min() > 0
    mask = np.zeros((n, n), bool)
    real_mask = np.zeros((n, n), bool)
    r0 = 0
    for b in _square_blocks(blocks):
        sl = slice(r0, r0 + b.rows)
        mask[sl, sl] = True
        if b.kind == "real":
            real_mask[sl, sl] = True
        if b.kind == "full":  # a full block commutes only with a scalar multiple of I
            blk = D[sl, sl]
            np.testing.assert_allclose(blk, blk[0, 0] * np.eye(b.rows),
                                       atol=1e-10 * abs(blk[0, 0]))
        r0 += b.rows
    assert np.all(D[~mask] == 0)
    if G is not None:
        np.testing.assert_allclose(G, G.conj().T, atol=1e-10 * (1 + np.linalg.norm(G, 2)))
        assert np.all(G[~real_mask] == 0)


def _check_mixed(M: np.ndarray, blocks: list[Block], r: MixedMuUpper) -> None:
    Mp, _ = BlockStructure(blocks).pad(np.asarray(M, complex))
    assert r.value >= 0 and np.isfinite(r.value)
    _assert_structured(r.D, r.G, blocks)
    assert _lmi_max(Mp, r.D, r.G, r.value) <= _tol(Mp, r.D, r.value)


def _check_scaling(M: np.ndarray, blocks: list[Block], upper: float, scaling) -> None:
    """mu_bounds' certificate: D = left^H left (square structures), G = scaling.g."""
    D = scaling.left.conj().T @ scaling.left
    if scaling.g is None:  # D-scaling bound: sigma_max(left M right^-1) <= upper
        assert float(np.linalg.norm(scaling.scaled(M), 2)) <= upper * (1 + 1e-9) + 1e-12
        return
    _assert_structured(D, scaling.g, blocks)
    assert _lmi_max(M, D, scaling.g, upper) <= _tol(M, D, upper)


_BLOCK = hs.one_of(
    hs.integers(1, 3).map(Block.real),
    hs.integers(1, 2).map(Block.repeated_complex),
    hs.tuples(hs.integers(1, 2), hs.integers(1, 2)).map(lambda rc: Block.full(*rc)),
)


@hs.composite
def _problem(draw: hs.DrawFn, square: bool = False) -> tuple[np.ndarray, list[Block]]:
    blocks = draw(hs.lists(_BLOCK, min_size=1, max_size=4).filter(
        lambda bl: sum(max(b.rows, b.cols) for b in bl) <= 6))
    if square:
        blocks = _square_blocks(blocks)
    rows, cols = BlockStructure(blocks).m_shape
    rng = np.random.default_rng(draw(hs.integers(0, 2**32 - 1)))
    kind = draw(hs.sampled_from(["complex", "real", "imaginary", "rank1"]))
    if kind == "rank1":
        M = np.outer(rng.standard_normal(rows) + 1j * rng.standard_normal(rows),
                     rng.standard_normal(cols) + 1j * rng.standard_normal(cols))
    else:
        M = rng.standard_normal((rows, cols)) + 1j * rng.standard_normal((rows, cols))
        M = {"complex": M, "real": M.real + 0j, "imaginary": 1j * M.imag}[kind]
    return M * 10.0 ** draw(hs.integers(-2, 2)), blocks


@_SETTINGS
@given(_problem())
def test_every_mixed_mu_certificate_proves_its_bound(problem) -> None:
    M, blocks = problem
    r = mixed_mu_upper(M, blocks)
    _check_mixed(M, blocks, r)
    assert r.value <= np.linalg.norm(M, 2) * (1 + 1e-9) + 1e-12  # D = I, G = 0 is feasible
    b = mixed_mu_bounds(M, blocks, n_starts=1)
    _check_mixed(M, blocks, b.certificate)
    assert b.lower <= b.upper * (1 + 1e-6) + 1e-12


@_SETTINGS
@given(_problem(square=True))
def test_mu_bounds_and_mixed_mu_upper_agree_and_both_are_certified(problem) -> None:
    M, blocks = problem
    mixed = mixed_mu_upper(M, blocks)
    b = mu_bounds(M, blocks, n_starts=1)
    _check_mixed(M, blocks, mixed)
    _check_scaling(M, blocks, b.upper, b.scaling)
    # with real blocks both are the mixed D-G bound (AB13MD, or the D-G optimiser where
    # AB13MD does not apply or its scalings fail); complex only: D-scaling and D-G with G = 0
    # minimise the same convex bound
    assert b.upper == pytest.approx(mixed.value, rel=2e-3, abs=1e-6 * np.linalg.norm(M, 2))
    assert b.lower <= mixed.value * (1 + 1e-6) + 1e-12


def test_ab13md_scalings_that_do_not_prove_its_value_are_not_returned() -> None:
    # issue 23: AB13MD returns 0 for M = 6.78j with one real scalar, with D = 1, G = 0, which
    # prove only 6.78. mu is 0 here (det(1 - 6.78j delta) != 0 for real delta): the D-G
    # optimiser certifies 0 with G > 0
    M = np.array([[6.78j]])
    r = mixed_mu_upper(M, [Block.real(1)])
    _check_mixed(M, [Block.real(1)], r)
    assert r.method == "dg"
    assert r.value <= 1e-6
    up, scaling = mu_upper_bound(M, [Block.real(1)])
    assert up == pytest.approx(r.value, abs=1e-6)
    _check_scaling(M, [Block.real(1)], up, scaling)
    assert mu_bounds(M, [Block.real(1)]).upper <= 1e-6
    # the old certificate indeed fails: 45.97 > 0
    assert _lmi_max(M, np.eye(1), np.zeros((1, 1)), 0.0) == pytest.approx(6.78**2)


def test_certified_value_is_the_smallest_beta_the_scalings_prove() -> None:
    rng = np.random.default_rng(5)
    M = rng.standard_normal((3, 3)) + 1j * rng.standard_normal((3, 3))
    D = np.diag([1.0, 2.0, 0.5]).astype(complex)
    G = np.diag([0.3, 0.0, 0.0]).astype(complex)
    beta = certified_value(M, D, G)
    assert _lmi_max(M, D, G, beta) == pytest.approx(0.0, abs=1e-9 * beta**2)
    assert _lmi_max(M, D, G, 0.999 * beta) > 0
    assert certified_value(M, np.eye(3), None) == pytest.approx(np.linalg.norm(M, 2))
