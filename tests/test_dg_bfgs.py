"""The compiled BFGS of the D-G bound (synthesis/dg_bfgs.py) against the path it replaced:
SciPy's BFGS (``scipy.optimize.minimize(method="BFGS")``) on the same objective with the same
continuation and stop callback, written out here as the reference. The same steps give the
same bound bit for bit on ordinary matrices; on badly scaled ones (scalings drifting to the
parameter wall) rounding may send the two elsewhere, so there the bounds are only compared
as a distribution; every bound is the value its (D, G) prove."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from scipy.optimize import minimize

from vtolftc.synthesis import dg_scaling as dgs
from vtolftc.synthesis.mu import Block
from vtolftc.synthesis.mu_blocks import BlockStructure

STRUCTURES = [
    [Block.real(3), Block.real(1)],                                  # the certificate's
    [Block.real(2), Block.real(1)],
    [Block.real(1), Block.full(2)],
    [Block.full(1), Block.full(2)],
    [Block.real(1), Block.real(1), Block.real(1)],
    [Block.real(2), Block.real(2)],
    [Block.real(3), Block.real(1), Block.repeated_complex(3), Block.repeated_complex(1)],
    [Block.real(1), Block.repeated_complex(2), Block.full(1)],
]


def _reference(M: np.ndarray, st: BlockStructure, x0: np.ndarray | None, target: float,
               rtol: float, maxiter: int) -> tuple[float, np.ndarray]:
    """The removed SciPy path of ``dg_upper_bound``: (best lambda_max, its parameters)."""
    par = dgs._dg_parametrisation(st.blocks)
    obj = dgs._DGObjective(M, par)
    starts = [np.zeros(par.n_params), dgs._osborne_x(M, par)]
    if x0 is not None:
        starts.append(np.asarray(x0, dtype=float))
    vals = [obj.value(s) for s in starts]
    k0 = int(np.argmin(vals))
    x = starts[k0].copy()
    stop2 = (target * (1.0 + rtol)) ** 2 if target > 0 else -math.inf
    warm = x0 is not None and k0 == len(starts) - 1

    def done() -> bool:
        return obj.best < 0.0 or obj.best <= stop2

    for rel in (dgs._WARM_STAGES if warm else dgs._COLD_STAGES):
        if done():
            break
        obj.smooth = rel
        hist: list[float] = []

        def _cb(intermediate_result: Any, hist: list[float] = hist) -> None:
            hist.append(obj.best)
            if done() or (len(hist) > 8 and hist[-9] - hist[-1] <= rtol * abs(hist[-1])):
                raise StopIteration

        opts = {"maxiter": maxiter, "gtol": 1e-12 * max(abs(obj.best), 1e-300)}
        res = minimize(obj, x, jac=True, method="BFGS", callback=_cb, options=opts)
        x = obj.best_x if obj.best_x is not None else np.asarray(res.x)
    assert obj.best_x is not None
    return obj.best, obj.best_x


def _case(rng: np.random.Generator, blocks: list[Block], kind: str) -> np.ndarray:
    n, m = BlockStructure(blocks).m_shape
    M = rng.normal(size=(n, m)) + 1j * rng.normal(size=(n, m))
    if kind == "near-real":
        M = M.real + 1e-3j * M.imag
    elif kind == "rank-one":
        M = np.outer(M[:, 0], M[0, :])
    elif kind == "scaled":
        d = np.exp(3.0 * rng.normal(size=n))
        M = d[:, None] * M / d[None, :m]
    return M


def _both(M: np.ndarray, blocks: list[Block], x0: np.ndarray | None = None,
          target: float = 0.0, rtol: float = 1e-9, maxiter: int = 200
          ) -> tuple[dgs.MixedMuUpper, float, np.ndarray, np.ndarray, BlockStructure]:
    st = BlockStructure(blocks)
    Mp, sq = st.pad(st.check(M))
    new = dgs.dg_upper_bound(Mp, sq, x0, target, rtol, maxiter)
    ref_best, ref_x = _reference(Mp, sq, x0, target, rtol, maxiter)
    return new, ref_best, ref_x, Mp, sq


@pytest.mark.parametrize("k", range(len(STRUCTURES)))
@pytest.mark.parametrize("kind", ["plain", "near-real", "rank-one"])
def test_same_bound_bit_for_bit_as_scipy_bfgs(k: int, kind: str) -> None:
    """Cold starts, warm starts (a neighbouring matrix's scalings, as in a frequency sweep),
    a target that stops early and a small iteration cap: the parameters and the bound of the
    reference, bit for bit."""
    rng = np.random.default_rng(100 * k + len(kind))
    blocks = STRUCTURES[k]
    for _ in range(2):
        M = _case(rng, blocks, kind)
        new, ref_best, ref_x, Mp, _ = _both(M, blocks)
        np.testing.assert_array_equal(new.params, ref_x)
        assert new.value == max(math.sqrt(max(ref_best, 0.0)),
                                dgs.certified_value(Mp, new.D, new.G))
        warm, _, w_x, _, _ = _both(M * (1.0 + 0.05j), blocks, x0=new.params)
        np.testing.assert_array_equal(warm.params, w_x)
        early, _, e_x, _, _ = _both(M, blocks, target=1.05 * new.value, rtol=1e-6)
        np.testing.assert_array_equal(early.params, e_x)
        # the cold path to convergence passes below the target: the early stop is there
        assert early.value <= 1.05 * new.value * (1 + 1e-6) * (1 + 1e-9)
        capped, _, c_x, _, _ = _both(M, blocks, maxiter=3)
        np.testing.assert_array_equal(capped.params, c_x)


def test_bounds_over_a_random_set_match_the_reference() -> None:
    """Badly scaled matrices included (scalings at the |x| = 300 wall, mu near 0): most bounds
    bit for bit the reference's, none more than 1e-3 relative above it outside the few
    where both are far from converged (the reference itself is rounding-sensitive there)."""
    rng = np.random.default_rng(7)
    rel = []
    for k, blocks in enumerate(STRUCTURES):
        for kind in ("plain", "scaled", "near-real", "rank-one"):
            M = _case(rng, blocks, kind)
            new, ref_best, ref_x, Mp, sq = _both(M, blocks)
            D, G = dgs._dg_parametrisation(sq.blocks).matrices(ref_x)
            ref = max(math.sqrt(max(ref_best, 0.0)), dgs.certified_value(Mp, D, G))
            rel.append((new.value - ref) / max(ref, 1e-12))
            # every returned bound is what its scalings prove (or more)
            assert new.value >= dgs.certified_value(Mp, new.D, new.G) * (1 - 1e-12), k
    r = np.array(rel)
    assert np.mean(r == 0.0) >= 0.85, r
    assert np.sum(r > 1e-3) <= 1, r


def test_zero_matrix_and_a_real_block_with_imaginary_entry() -> None:
    """mu = 0 cases: M = 0 (bound 0 at the start), and M = 6.78j on one real scalar (the
    bound falls towards 0 as G grows): the reference's parameters bit for bit."""
    z, _, zx, _, _ = _both(np.zeros((2, 2), complex), [Block.real(2)])
    assert z.value == 0.0
    np.testing.assert_array_equal(z.params, zx)
    j, _, jx, _, _ = _both(np.array([[6.78j]]), [Block.real(1)])
    np.testing.assert_array_equal(j.params, jx)
    assert j.value <= 1e-6
