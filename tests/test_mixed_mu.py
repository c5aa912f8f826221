"""Tests of vtolftc.synthesis.mixed_mu (mixed real/complex mu: D-G upper bound, lower bound)."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.synthesis.hinfnorm import frequency_response
from vtolftc.synthesis.mixed_mu import (
    BlockStructure,
    MixedMuUpper,
    mixed_mu_bounds,
    mixed_mu_lower,
    mixed_mu_sweep,
    mixed_mu_upper,
)
from vtolftc.synthesis.mu import Block, mu_upper_bound

# SLICOT AB13MD documentation example (AB13MD.dat / AB13MD.res): two real scalars, a 2x2 and
# two 1x1 complex blocks; upper bound 0.4174753408e+02
_Z_ROW = [
    -1 + 6j, 2 - 3j, 3 + 8j, 3 + 8j, -5 - 9j, -6 + 2j,
    4 + 2j, -2 + 5j, -6 - 7j, -4 + 11j, 8 - 7j, 12 - 1j,
    5 - 4j, -4 - 8j, 1 - 3j, -6 + 14j, 2 - 5j, 4 + 16j,
]
AB13MD_Z = np.array(_Z_ROW + _Z_ROW, dtype=complex).reshape(6, 6)
AB13MD_BLOCKS = [Block.real(1), Block.real(1), Block.full(2), Block.full(1), Block.full(1)]
AB13MD_MU = 41.74753408


def _certificate_holds(M: np.ndarray, r: MixedMuUpper, st: BlockStructure) -> bool:
    Mp, _ = st.pad(np.asarray(M, complex))
    H = Mp.conj().T @ r.D @ Mp + 1j * (r.G @ Mp - Mp.conj().T @ r.G) - r.value**2 * r.D
    lam = np.linalg.eigvalsh(0.5 * (H + H.conj().T))
    return bool(lam.max() <= 1e-9 * max(r.value**2, 1e-12) * np.linalg.norm(r.D, 2))


def _assert_destabilising(M: np.ndarray, Delta: np.ndarray, value: float) -> None:
    n = M.shape[0]
    smin = np.linalg.svd(np.eye(n) - M @ Delta, compute_uv=False)[-1]
    assert smin < 1e-7 * (1 + np.linalg.norm(M, 2) * np.linalg.norm(Delta, 2))
    assert np.linalg.norm(Delta, 2) == pytest.approx(1 / value, rel=1e-9)


@pytest.mark.parametrize("method", ["dg", "ab13md", "auto"])
def test_ab13md_documentation_example(method: str) -> None:
    r = mixed_mu_upper(AB13MD_Z, AB13MD_BLOCKS, method=method)
    assert r.value == pytest.approx(AB13MD_MU, rel=1e-8)  # 8 significant digits
    assert r.method == ("dg" if method == "dg" else "ab13md")
    if method == "dg":
        assert _certificate_holds(AB13MD_Z, r, BlockStructure(AB13MD_BLOCKS))
    # treating the real blocks as complex is strictly more conservative (41.977)
    up_c, _ = mu_upper_bound(AB13MD_Z, AB13MD_BLOCKS, method="dscale")
    assert up_c > AB13MD_MU * 1.005


def test_closed_form_real_cases() -> None:
    # diag(1, 2j) with a repeated real scalar: only delta = 1 is real-destabilising -> mu = 1
    M = np.diag([1.0, 2.0j])
    r = mixed_mu_upper(M, [Block.real(2)])
    assert r.value == pytest.approx(1.0, rel=1e-7)
    lo, Delta = mixed_mu_lower(M, [Block.real(2)])
    assert lo == pytest.approx(1.0, rel=1e-12)
    assert Delta is not None
    _assert_destabilising(M, Delta, lo)
    # the complex bound says 2 (= rho(M)): the G scaling is what brings it to 1
    assert mu_upper_bound(M, [Block.real(2)], method="dscale")[0] == pytest.approx(2.0)
    # [[0, 1], [-1, 0]] with a repeated real scalar: det(I - d M) = 1 + d^2 > 0 -> mu = 0
    J = np.array([[0.0, 1.0], [-1.0, 0.0]])
    r = mixed_mu_upper(J, [Block.real(2)])
    assert r.value <= 1e-6  # the D-G bound certifies 0 exactly (value 0.0)
    assert mixed_mu_lower(J, [Block.real(2)])[0] == 0.0
    # mu of a single real scalar 1x1: |m| if m is real, 0 otherwise
    assert mixed_mu_upper(np.array([[0.7]]), [Block.real(1)], method="dg").value == (
        pytest.approx(0.7, rel=1e-9))
    assert mixed_mu_upper(np.array([[0.7j]]), [Block.real(1)], method="dg").value <= 1e-6


def _brute_real_complex(M: np.ndarray, grid: np.ndarray) -> float:
    """mu for Delta = diag(d (real), c (complex)) by brute force over d.

    det(I - M diag(d, c)) = 0 is linear in c: c = (1 - m11 d) / (m22 (1 - m11 d) + m12 m21 d);
    the smallest max(|d|, |c|) over a dense grid of d gives mu = 1 / that.
    """
    m11, m12, m21, m22 = M[0, 0], M[0, 1], M[1, 0], M[1, 1]
    from scipy.optimize import minimize_scalar

    def size(d: np.ndarray) -> np.ndarray:
        den = m22 * (1 - m11 * d) + m12 * m21 * d
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.abs((1 - m11 * d) / den)
        return np.maximum(np.abs(d), c)

    s = size(grid)
    k = int(np.nanargmin(s))
    res = minimize_scalar(lambda d: float(size(np.array([d]))[0]),
                          bounds=(grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]),
                          method="bounded", options={"xatol": 1e-14})
    return 1.0 / min(float(s[k]), float(res.fun))


def _brute_two_real(M: np.ndarray, grid: np.ndarray) -> float:
    """mu for Delta = diag(d1, d2) (both real) and complex M by brute force over d1.

    det = 1 - m11 d1 - m22 d2 + det(M) d1 d2 = 0 gives d2(d1) = (1 - m11 d1)/(m22 - det d1);
    it is admissible where Im d2 = 0: sign changes on a dense grid, refined by bisection.
    """
    m11, m22, dt = M[0, 0], M[1, 1], np.linalg.det(M)

    def d2(d1: np.ndarray) -> np.ndarray:
        return (1 - m11 * d1) / (m22 - dt * d1)

    im = d2(grid).imag
    best = np.inf
    for k in np.flatnonzero(np.sign(im[:-1]) * np.sign(im[1:]) < 0):
        a, b = grid[k], grid[k + 1]
        for _ in range(60):
            c = 0.5 * (a + b)
            if np.sign(d2(np.array([c]))[0].imag) == np.sign(d2(np.array([a]))[0].imag):
                a = c
            else:
                b = c
        v = d2(np.array([0.5 * (a + b)]))[0]
        if abs(v.imag) < 1e-6 * (1 + abs(v)):
            best = min(best, max(abs(0.5 * (a + b)), abs(v.real)))
    return 0.0 if not np.isfinite(best) else 1.0 / best


def test_brute_force_real_parametric_families() -> None:
    """Two-parameter families (real x complex, real x real with complex M) against brute force.

    The lower bound is exact on both (when written: all 24 cases to 1e-7); the D-G upper
    bound is tight for real x complex and conservative for two reals (up to 2.2x here: the
    classic gap of the real-mu bound, real mu being discontinuous).
    """
    rng = np.random.default_rng(11)
    grid = np.concatenate([-np.geomspace(1e-3, 1e3, 40001)[::-1], np.geomspace(1e-3, 1e3, 40001)])
    n_zero = 0
    for _ in range(8):
        M = rng.standard_normal((2, 2)) + 1j * rng.standard_normal((2, 2))
        # real x complex
        exact = _brute_real_complex(M, grid)
        b = mixed_mu_bounds(M, [Block.real(1), Block.full(1)])
        assert b.lower == pytest.approx(exact, rel=1e-6)
        assert b.upper >= exact * (1 - 1e-7)
        assert b.upper <= exact * (1 + 1e-3)
        dg = mixed_mu_upper(M, [Block.real(1), Block.full(1)], method="dg").value
        assert exact * (1 - 1e-7) <= dg <= exact * (1 + 1e-3)
        # real x real (complex M)
        exact = _brute_two_real(M, grid)
        b = mixed_mu_bounds(M, [Block.real(1), Block.real(1)])
        assert b.lower == pytest.approx(exact, rel=1e-6, abs=1e-12)
        assert b.upper >= exact * (1 - 1e-7)
        n_zero += exact == 0.0
        if exact == 0.0:
            assert b.upper <= 1e-6  # mu = 0 certified
    assert 0 < n_zero < 8  # the family contains both kinds


def test_repeated_real_brute_force() -> None:
    """delta I_2 (real) x one complex scalar: brute force over delta, exact complex part."""
    rng = np.random.default_rng(12)
    grid = np.concatenate([-np.geomspace(1e-3, 1e3, 100001)[::-1], np.geomspace(1e-3, 1e3, 100001)])
    blocks = [Block.real(2), Block.full(1)]
    for _ in range(6):
        M = rng.standard_normal((3, 3)) + 1j * rng.standard_normal((3, 3))
        # complex part for fixed real d: LFT M' = M22 + M21 d (I - M11 d)^-1 M12 (scalar)
        M11, M12, M21, M22 = M[:2, :2], M[:2, 2:], M[2:, :2], M[2:, 2:]
        d = grid[::5]
        rhs = np.broadcast_to(M12, (d.size, 2, 1))
        X = np.linalg.solve(np.eye(2) - d[:, None, None] * M11, rhs)
        mp = np.abs(M22[0, 0] + d * (M21 @ X)[:, 0, 0])
        with np.errstate(divide="ignore"):
            best = float(np.min(np.maximum(np.abs(d), 1 / mp)))
        for lam in np.linalg.eigvals(M11):  # I - d M11 singular at real d = 1/lambda
            if abs(lam.imag) < 1e-12 * abs(lam):
                best = min(best, abs(1 / lam.real))
        exact = 1 / best
        b = mixed_mu_bounds(M, blocks)
        assert b.lower <= exact * (1 + 1e-3)  # grid resolution
        assert b.upper >= exact * (1 - 1e-3)
        assert b.lower <= b.upper * (1 + 1e-9)


@pytest.mark.parametrize(
    "blocks",
    [
        [Block.real(2), Block.full(2), Block.full(1)],
        [Block.real(1), Block.real(3), Block.full(2)],
        [Block.real(2), Block.repeated_complex(2), Block.full(1, 2)],
        [Block.full(1, 2), Block.real(1), Block.full(3, 1)],
    ],
    ids=["rep-real", "two-real", "rep-both-nonsquare", "nonsquare"],
)
def test_upper_above_lower_random(blocks: list[Block]) -> None:
    st = BlockStructure(blocks)
    rng = np.random.default_rng(3)
    for _ in range(6):
        M = rng.standard_normal(st.m_shape) + 1j * rng.standard_normal(st.m_shape)
        b = mixed_mu_bounds(M, st, n_starts=2)
        assert b.lower <= b.upper * (1 + 1e-9)
        assert b.upper <= np.linalg.norm(M, 2) * (1 + 1e-9)
        assert _certificate_holds(M, b.certificate, st)
        if b.lower > 0:
            assert b.delta is not None and b.delta.shape == st.delta_shape
            _assert_destabilising(M, b.delta, b.lower)


def test_agrees_with_ab13md_on_random_structures() -> None:
    rng = np.random.default_rng(8)
    blocks = [Block.real(1), Block.full(2), Block.real(1), Block.full(1)]
    for _ in range(10):
        M = rng.standard_normal((5, 5)) + 1j * rng.standard_normal((5, 5))
        a = mixed_mu_upper(M, blocks, method="ab13md").value
        d = mixed_mu_upper(M, blocks, method="dg").value
        assert d == pytest.approx(a, rel=1e-5)


def test_nonsquare_padding_is_exact() -> None:
    """A 1x2 and a 2x1 full block: mu equals that of the zero-padded square problem."""
    rng = np.random.default_rng(1)
    blocks = [Block.full(1, 2), Block.full(2, 1)]
    st = BlockStructure(blocks)
    assert st.m_shape == (3, 3) and st.delta_shape == (3, 3)
    blocks2 = [Block.full(2, 1), Block.real(1)]
    st2 = BlockStructure(blocks2)
    assert st2.m_shape == (2, 3)
    M = rng.standard_normal((2, 3)) + 1j * rng.standard_normal((2, 3))
    b = mixed_mu_bounds(M, blocks2)
    Mp, sq = st2.pad(M)
    assert Mp.shape == (3, 3)
    assert mixed_mu_upper(Mp, sq, method="dg").value == pytest.approx(b.upper, rel=1e-6)
    with pytest.raises(ValueError, match="needs 2x3"):
        mixed_mu_upper(np.ones((3, 3)), blocks2)


def test_sweep_bounds_and_pointwise_consistency() -> None:
    import control

    np.random.seed(4)
    sys = control.rss(6, 5, 5)
    w = np.logspace(-1, 1, 25)
    F = frequency_response(sys, w)
    blocks = [Block.real(2), Block.real(1), Block.full(2)]
    sw = mixed_mu_sweep(F, blocks, w, rtol=1e-6)
    assert np.all(sw.lower <= sw.upper * (1 + 1e-9))
    assert sw.peak_upper == sw.upper.max()
    k = 9
    single = mixed_mu_upper(F[k], blocks, method="dg")
    assert sw.upper[k] <= single.value * (1 + 1e-3) + 1e-12
    assert sw.upper[k] >= mixed_mu_lower(F[k], blocks)[0] * (1 - 1e-9)
    with pytest.raises(ValueError, match="freq_response must have shape"):
        mixed_mu_sweep(F[:, :4, :4], blocks, w)


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="unknown method"):
        mixed_mu_upper(np.eye(2), [Block.full(2)], method="lmi")
    with pytest.raises(ValueError, match="AB13MD only takes"):
        mixed_mu_upper(np.eye(2), [Block.real(2)], method="ab13md")
    with pytest.raises(ValueError, match="empty"):
        BlockStructure([])


def _msd_loop() -> tuple[np.ndarray, ...]:
    """Mass-spring-damper under PD control, uncertain k, c (real) and actuator (complex)."""
    m, k0, c0, kp, kd = 1.0, 1.0, 0.2, 2.0, 0.4
    A = np.array([[0, 1], [-(k0 + kp) / m, -(c0 + kd) / m]])
    B = np.array([[0, 0, 0], [-0.4 * k0 / m, -0.5 * c0 / m, 0.1 / m]])
    C = np.array([[1, 0], [0, 1], [-kp, -kd]])
    return A, B, C, np.zeros((3, 3))


def test_sweep_with_ab13md_structure_readme_example() -> None:
    """The README's mixed-mu example (AB13MD path over 200 frequencies; once hung when AB13MD
    was warm-started along the sweep)."""
    from vtolftc.synthesis.mu import mu_sweep

    w = np.logspace(-1, 1, 200)
    F = frequency_response(_msd_loop(), w)
    blocks = [Block.real(1), Block.real(1), Block.full(1)]
    mixed = mixed_mu_sweep(F, blocks, w)
    cplx = mu_sweep(F, [Block.full(1)] * 3, w)
    assert np.all(mixed.lower <= mixed.upper * (1 + 1e-9))
    assert mixed.peak_lower == pytest.approx(mixed.peak_upper, rel=1e-3)
    assert mixed.peak_upper < 0.6 * cplx.peak_upper  # the real structure is worth 1.85x
    # brute force over the two real parameters with the complex block solved exactly
    k = int(np.argmax(mixed.upper))
    M = F[k]
    g = np.linspace(-3, 3, 401)
    dk, dc = (x.ravel() for x in np.meshgrid(g, g))
    Dr = np.zeros((dk.size, 2, 2))
    Dr[:, 0, 0], Dr[:, 1, 1] = dk, dc
    X = np.linalg.solve(np.eye(2) - M[:2, :2] @ Dr, np.broadcast_to(M[:2, 2:], (dk.size, 2, 1)))
    mp = np.abs(M[2, 2] + (M[2:, :2] @ Dr @ X)[:, 0, 0])
    with np.errstate(divide="ignore"):
        best = float(np.min(np.maximum(np.maximum(np.abs(dk), np.abs(dc)), 1 / mp)))
    assert mixed.upper[k] >= (1 / best) * (1 - 2e-2)  # grid resolution 1.5e-2
    assert mixed.lower[k] <= (1 / best) * (1 + 2e-2)
