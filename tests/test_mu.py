"""Tests of vtolftc.synthesis.mu (structured singular value bounds, paper eqs. 12-14)."""

from __future__ import annotations

import control
import numpy as np
import pytest

from vtolftc.synthesis.hinfnorm import frequency_response
from vtolftc.synthesis.mu import (
    Block,
    MuBounds,
    mu_bounds,
    mu_lower_bound,
    mu_sweep,
    mu_upper_bound,
)


def _crandn(rng: np.random.Generator, *shape: int) -> np.ndarray:
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


def _assert_destabilising(M: np.ndarray, delta: np.ndarray, lower: float) -> None:
    n = M.shape[0]
    smin = np.linalg.svd(np.eye(n) - M @ delta, compute_uv=False)[-1]
    assert smin < 1e-8 * (1 + np.linalg.norm(M, 2) * np.linalg.norm(delta, 2))
    assert np.linalg.norm(delta, 2) == pytest.approx(1.0 / lower, rel=1e-9)


def test_single_full_block_is_sigma_max() -> None:
    rng = np.random.default_rng(0)
    M = _crandn(rng, 4, 4)
    res = mu_bounds(M, [Block.full(4)])
    smax = np.linalg.norm(M, 2)
    assert res.upper == pytest.approx(smax, rel=1e-12)
    assert res.lower == pytest.approx(smax, rel=1e-8)
    assert res.delta is not None
    _assert_destabilising(M, res.delta, res.lower)


def test_single_repeated_complex_block_is_spectral_radius() -> None:
    rng = np.random.default_rng(1)
    for n in (2, 3, 5):
        M = _crandn(rng, n, n)
        rho = max(abs(np.linalg.eigvals(M)))
        res = mu_bounds(M, [Block.repeated_complex(n)])
        assert res.lower == pytest.approx(rho, rel=1e-9)
        assert res.upper == pytest.approx(rho, rel=1e-6)


def test_rank_one_scalar_blocks_sum_rule() -> None:
    """mu(u v^H) with scalar complex blocks = sum_i |u_i v_i| (SISO RP: |Ws S| + |Wt T|)."""
    rng = np.random.default_rng(2)
    for n in (2, 3, 4):
        u, v = _crandn(rng, n), _crandn(rng, n)
        M = np.outer(u, v.conj())
        exact = float(np.sum(np.abs(u * v)))
        res = mu_bounds(M, [Block.full(1)] * n)
        assert res.lower == pytest.approx(exact, rel=1e-6)
        assert res.upper == pytest.approx(exact, rel=1e-5)
    # the robust-performance matrix N = [[wt T, wt T], [ws S, ws S]] at one frequency
    s = 1j * 0.7
    G, K = 1.0 / (s * (s + 1.0)), 2.0
    S, T = 1.0 / (1 + G * K), G * K / (1 + G * K)
    ws, wt = 0.8 / (s + 0.1), 0.3 * (s + 1.0) / (0.1 * s + 1.0)
    N = np.array([[wt * T, wt * T], [ws * S, ws * S]])
    res = mu_bounds(N, [Block.full(1), Block.full(1)])
    assert res.upper == pytest.approx(abs(ws * S) + abs(wt * T), rel=1e-6)
    assert res.lower == pytest.approx(abs(ws * S) + abs(wt * T), rel=1e-6)


STRUCTURES = [
    [Block.full(1)] * 4,
    [Block.full(2), Block.full(1), Block.full(1)],
    [Block.repeated_complex(2), Block.full(2)],
    [Block.repeated_complex(2), Block.full(1), Block.full(1)],
    [Block.full(1, 2), Block.full(2, 1), Block.full(1)],
    [Block.real(1), Block.full(1), Block.full(2)],
    [Block.real(2), Block.repeated_complex(2)],
    [Block.real(1), Block.real(1), Block.full(2)],
]


@pytest.mark.parametrize("blocks", STRUCTURES, ids=lambda b: "-".join(x.kind[:4] for x in b))
def test_random_mixed_structures_bound_relations(blocks: list[Block]) -> None:
    rng = np.random.default_rng(4)
    all_square = all(b.rows == b.cols for b in blocks)
    all_complex = all(b.kind != "real" for b in blocks)
    for _ in range(6):
        M = _crandn(rng, 4, 4)
        res = mu_bounds(M, blocks)
        assert isinstance(res, MuBounds)
        assert res.lower <= res.upper * (1 + 1e-9)
        assert res.upper <= np.linalg.norm(M, 2) * (1 + 1e-12)
        assert res.gap == pytest.approx(res.upper - res.lower)
        if all_square and all_complex:
            assert res.lower >= max(abs(np.linalg.eigvals(M))) * (1 - 1e-9)
        if res.lower > 0:
            assert res.delta is not None
            _assert_destabilising(M, res.delta, res.lower)
            # the destabilising perturbation respects the structure
            r0 = c0 = 0
            mask = np.zeros((4, 4), bool)
            for b in blocks:
                mask[c0 : c0 + b.rows, r0 : r0 + b.cols] = True
                blk = res.delta[c0 : c0 + b.rows, r0 : r0 + b.cols]
                if b.kind != "full":
                    assert np.allclose(blk, blk[0, 0] * np.eye(b.rows))
                if b.kind == "real":
                    assert abs(blk[0, 0].imag) < 1e-12
                r0 += b.cols
                c0 += b.rows
            assert np.all(res.delta[~mask] == 0)
        # the returned scaling reproduces the upper bound (D-G certificate with real blocks)
        assert res.scaling is not None
        if res.scaling.g is None:
            assert np.linalg.norm(res.scaling.scaled(M), 2) == pytest.approx(res.upper, rel=1e-9)
        else:
            D = res.scaling.left.conj().T @ res.scaling.left
            G = res.scaling.g
            H = M.conj().T @ D @ M + 1j * (G @ M - M.conj().T @ G) - res.upper**2 * D
            assert np.linalg.eigvalsh(0.5 * (H + H.conj().T)).max() <= 1e-9 * res.upper**2
        # the real-aware bound is never worse than treating real blocks as complex
        if not all_complex and all_square:
            up_c, _ = mu_upper_bound(M, blocks, method="dscale")
            assert res.upper <= up_c * (1 + 1e-6)


def test_real_block_lower_bound_exact_for_real_eigenvalue() -> None:
    M = np.array([[0.5, 2.0], [0.0, -3.0]])
    val, delta = mu_lower_bound(M, [Block.real(2)])
    assert val == pytest.approx(3.0, rel=1e-12)
    assert delta is not None
    _assert_destabilising(M, delta, val)


def test_separate_functions_and_gap_reported() -> None:
    rng = np.random.default_rng(5)
    M = _crandn(rng, 4, 4)
    blocks = [Block.full(1)] * 4
    up, D = mu_upper_bound(M, blocks)
    lo, delta = mu_lower_bound(M, blocks, scaling=D, n_starts=6, seed=3)
    assert lo <= up * (1 + 1e-9)
    assert np.linalg.norm(D.left @ M @ np.linalg.inv(D.right), 2) == pytest.approx(up, rel=1e-9)
    assert delta is not None
    res = mu_bounds(M, blocks)
    assert res.relative_gap >= -1e-9
    assert res.relative_gap < 0.05


def test_sweep_peak() -> None:
    np.random.seed(7)
    for n in (2, 4):
        sys = control.rss(6, n, n)
        w = np.logspace(-2, 2, 200)
        F = frequency_response(sys, w)
        blocks = [Block.full(1)] * n
        sw = mu_sweep(F, blocks, w)  # speed: benchmarks/bench_toolbox.py, never a wall-clock test
        assert sw.lower.shape == sw.upper.shape == (200,)
        assert np.all(sw.lower <= sw.upper * (1 + 1e-9))
        assert sw.peak_upper == pytest.approx(sw.upper.max())
        assert sw.peak_upper_frequency_rad_s == w[int(np.argmax(sw.upper))]
        # spot-check one frequency against the standalone function
        k = 57
        single = mu_bounds(F[k], blocks)
        assert sw.upper[k] == pytest.approx(single.upper, rel=1e-3)


def test_bad_inputs() -> None:
    M = np.eye(3)
    with pytest.raises(ValueError, match="square"):
        mu_bounds(np.ones((2, 3)), [Block.full(2)])
    with pytest.raises(ValueError, match="block sizes do not match"):
        mu_bounds(M, [Block.full(1), Block.full(1)])
    with pytest.raises(ValueError, match="unknown block kind"):
        Block("diagonal", 1, 1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown block specification"):
        mu_bounds(M, [Block.full(1), (1, 1), Block.full(1)])  # type: ignore[list-item]
    with pytest.raises(ValueError, match="must be square"):
        Block("repeated_complex", 2, 3)
    with pytest.raises(ValueError, match="positive integer"):
        Block.full(0)
    with pytest.raises(ValueError, match=r"shape \(nw, n, n\)"):
        mu_sweep(np.ones((3, 2)), [Block.full(2)], np.ones(3))
    with pytest.raises(ValueError, match="omegas has"):
        mu_sweep(np.ones((3, 2, 2)), [Block.full(2)], np.ones(4))
