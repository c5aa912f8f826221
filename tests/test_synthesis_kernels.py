"""The compiled kernels of the synthesis against independent answers: the frequency-response
kernel of the structured tuner (numpy reference, finite differences, a known pole), the
rightmost-eigenvalue routine (scipy.linalg.eig, bit for bit), the mu power iteration (its
numpy reference) and the order of the report's figures."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from vtolftc.synthesis.freq_kernel import siso_sigma, siso_sigma_grad
from vtolftc.synthesis.mu import Block, _Power, mu_bounds
from vtolftc.synthesis.mu_blocks import BlockStructure
from vtolftc.synthesis.structured import (
    Parameter,
    TuningProblem,
    _Evaluator,
    _rightmost_eig,
)


def _stable(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.standard_normal((n, n))
    return A - (np.max(np.linalg.eigvals(A).real) + 0.5) * np.eye(n)


class _Family:
    """theta -> (A(theta), B(theta), C(theta), D(theta)): a smooth random family with
    ``inputs`` input columns (picklable, no realize_batch: the loop derivatives)."""

    def __init__(self, seed: int, n: int, q: int, inputs: int, p: int):
        rng = np.random.default_rng(seed)
        self.A0 = _stable(rng, n)
        self.Ak = 0.3 * rng.standard_normal((p, n, n))
        self.B0, self.Bk = rng.standard_normal((n, inputs)), rng.standard_normal((p, n, inputs))
        self.C0, self.Ck = rng.standard_normal((q, n)), rng.standard_normal((p, q, n))
        self.D0, self.Dk = rng.standard_normal((q, inputs)), rng.standard_normal((p, q, inputs))

    def __call__(self, th: np.ndarray) -> tuple[np.ndarray, ...]:
        s = np.sin(th)  # nonlinear in theta, so the derivatives are not constant
        return (self.A0 + np.einsum("k,kij->ij", s, self.Ak),
                self.B0 + np.einsum("k,kij->ij", th, self.Bk),
                self.C0 + np.einsum("k,kij->ij", th**2, self.Ck),
                self.D0 + np.einsum("k,kij->ij", th, self.Dk))


def _problem(q: int, inputs: int, seed: int = 0, p: int = 3) -> TuningProblem:
    params = [Parameter(f"t{k}", 0.1 * (k + 1), -1.0, 1.0) for k in range(p)]
    chans = [_Family(seed + i, 5 + 2 * i, q, inputs, p) for i in range(2)]
    return TuningProblem(params, chans)


@pytest.mark.parametrize("q", [1, 3])
def test_frequency_kernel_matches_the_numpy_reference_and_finite_differences(q: int) -> None:
    """sigma_max and its gradient from the compiled kernel equal the numpy path (batched
    solves, SVD, full dT products) to round-off, at finite frequencies and at w = inf, and
    the gradient is the central difference of sigma_max itself (an independent check)."""
    pb = _problem(q, 1, seed=3 * q)
    ev, ref = _Evaluator(pb), _Evaluator(pb)
    ref.compiled = False
    rng = np.random.default_rng(q)
    om = [np.r_[np.geomspace(0.01, 100.0, 9), np.inf], np.r_[0.0, np.geomspace(0.1, 30, 5)]]
    for _ in range(5):
        th = rng.uniform(-0.8, 0.8, 3)
        for grad in (False, True):
            s, g = ev.sigma_and_grad(th, om, grad)
            s_ref, g_ref = ref.sigma_and_grad(th, om, grad)
            np.testing.assert_allclose(s, s_ref, rtol=1e-12, atol=0)
            if grad:
                np.testing.assert_allclose(g, g_ref, rtol=1e-9, atol=1e-11 * np.abs(g_ref).max())
        _, g = ev.sigma_and_grad(th, om, True)
        h = 1e-6
        for k in range(3):
            tp, tm = th.copy(), th.copy()
            tp[k] += h
            tm[k] -= h
            fd = (ev.sigma_and_grad(tp, om, False)[0]
                  - ev.sigma_and_grad(tm, om, False)[0]) / (2 * h)
            np.testing.assert_allclose(g[:, k], fd, rtol=1e-5, atol=1e-7)


def test_multi_input_channels_take_the_numpy_path() -> None:
    pb = _problem(2, 2)
    ev, ref = _Evaluator(pb), _Evaluator(pb)
    ref.compiled = False
    th = np.array([0.2, -0.3, 0.5])
    om = [np.geomspace(0.1, 10, 4)] * 2
    s, g = ev.sigma_and_grad(th, om, True)
    s_ref, g_ref = ref.sigma_and_grad(th, om, True)
    assert s.tobytes() == s_ref.tobytes() and g.tobytes() == g_ref.tobytes()
    # sigma_max of a 2 x 2 response is not the norm of one column: the kernel would be wrong
    A, B, C, D = pb.channels[0](th)
    T = C @ np.linalg.solve(1j * om[0][0] * np.eye(A.shape[0]) - A, B) + D
    assert s[0] == pytest.approx(np.linalg.svd(T, compute_uv=False)[0], rel=1e-12)


def test_frequency_kernel_reports_a_frequency_on_a_pole() -> None:
    A = np.array([[0.0, -1.0], [1.0, 0.0]])  # poles +-j: j*1 I - A is exactly singular
    B, C, D = np.array([[1.0], [0.0]]), np.array([[1.0, 0.0]]), np.zeros((1, 1))
    with pytest.raises(np.linalg.LinAlgError, match="pole"):
        siso_sigma(A, B, C, D, np.array([1.0]))
    z = np.zeros((1, 2, 2))
    s, g = siso_sigma_grad(A, B, C, D, np.array([0.5, np.inf]), z, np.zeros((1, 2, 1)),
                           np.zeros((1, 1, 2)), np.ones((1, 1, 1)))
    assert s[0] == pytest.approx(abs(0.5j / (0.5j**2 + 1)))  # s / (s^2 + 1) at s = 0.5 j
    assert s[1] == 0.0 and g[1, 0] == 1.0  # at w = inf only dD counts (u = e1 where T = 0)


def test_rightmost_eigenpair_is_scipys_bit_for_bit() -> None:
    rng = np.random.default_rng(11)
    for t in range(400):
        n = int(rng.integers(1, 15))
        A = rng.standard_normal((n, n))
        if t % 3 == 0:
            A = A + A.T  # real spectrum: real vectors
        if t % 7 == 0:
            A = np.triu(A)
        lam, vl, vr = scipy.linalg.eig(A, left=True, right=True)
        j = int(np.argmax(lam.real))
        mine = _rightmost_eig(A)
        assert mine[0] == lam[j]
        assert mine[1].dtype == vl.dtype and mine[1].tobytes() == vl[:, j].tobytes()
        assert mine[2].dtype == vr.dtype and mine[2].tobytes() == vr[:, j].tobytes()
    with pytest.raises(ValueError, match="infs or NaNs"):
        _rightmost_eig(np.array([[np.nan]]))


@pytest.mark.parametrize("blocks", [
    [Block.full(1, 1), Block.full(1, 1), Block.full(1, 1)],
    [Block.full(1, 3), Block.full(3, 1)],
    [Block.full(1, 1), Block.full(3, 3)],
    [Block.repeated_complex(2), Block.full(2, 2)],
    [Block.real(2), Block.full(1, 1)],
    [Block.real(1), Block.real(1), Block.full(2, 2)],
])
def test_power_iteration_kernel_matches_the_numpy_reference(blocks: list[Block]) -> None:
    st = BlockStructure(blocks).require_square(sum(b.cols for b in blocks))
    rng = np.random.default_rng(st.n)
    for _ in range(40):
        M = rng.standard_normal((st.n, st.n)) + 1j * rng.standard_normal((st.n, st.n))
        b = rng.standard_normal(st.n) + 1j * rng.standard_normal(st.n)
        w = rng.standard_normal(st.n) + 1j * rng.standard_normal(st.n)
        pw = _Power(M, st)
        for iters in (1, 7, 60):
            a1, w1 = pw.run(b / np.linalg.norm(b), w / np.linalg.norm(w), iters)
            a2, w2 = pw.run_numpy(b / np.linalg.norm(b), w / np.linalg.norm(w), iters)
            np.testing.assert_allclose(a1, a2, rtol=0, atol=1e-11)
            np.testing.assert_allclose(w1, w2, rtol=0, atol=1e-11)


def test_mu_of_a_rank_one_matrix_is_exact_with_the_kernel() -> None:
    """mu of M = u v^H with scalar complex blocks is sum_i |u_i v_i| (textbook: Packard and
    Doyle 1993); both bounds must reach it."""
    rng = np.random.default_rng(5)
    u = rng.standard_normal(4) + 1j * rng.standard_normal(4)
    v = rng.standard_normal(4) + 1j * rng.standard_normal(4)
    exact = float(np.sum(np.abs(u * np.conj(v))))
    r = mu_bounds(np.outer(u, np.conj(v)), [Block.full(1, 1)] * 4)
    assert r.lower == pytest.approx(exact, rel=1e-6)
    assert r.upper == pytest.approx(exact, rel=1e-4)


def test_report_figures_keep_their_order_whichever_job_finishes_first() -> None:
    from vtolftc.synthesis.report import png_order

    names = ["mu_yaw.png", "wt_pitch.png", "poles_roll.png", "mu_roll.png", "wt_roll.png",
             "poles_yaw.png", "wt_yaw.png"]
    assert png_order(names) == ["wt_roll.png", "wt_pitch.png", "wt_yaw.png", "poles_roll.png",
                                "poles_yaw.png", "mu_roll.png", "mu_yaw.png"]
