"""Tests of the generalized-plant API: vtolftc.synthesis.lft and vtolftc.synthesis.blocks."""

from __future__ import annotations

import itertools
import math

import control
import numpy as np
import pytest

from vtolftc.synthesis.blocks import (
    ControllerStructure,
    PIDBlock,
    PPIDBlock,
    StateSpaceBlock,
    StaticGain,
    lft_problem,
)
from vtolftc.synthesis.hinfnorm import frequency_response, hinf_norm
from vtolftc.synthesis.lft import GeneralizedPlant, lft
from vtolftc.synthesis.structured import Progress, tune

# COMPleib AC4 (Leibfritz), the static-output-feedback benchmark of issue 15
AC4 = {
    "A": [[-0.876, 1, -0.1209, 0], [8.9117, 0, -130.75, 0], [0, 0, -150, 0], [-1, 0, 0, -0.05]],
    "B1": [[0, 0], [0, 0], [0, 0], [0, 1]],
    "B2": [[0], [0], [150], [0]],
    "C1": [[-0.25, 0, 0, 3.487], [0, 0, -3, 0]],
    "C2": [[-1, 0, 0, 0], [0, -1, 0, 0]],
    "D11": [[0, 0.25], [0, 0]],
    "D12": [[0], [3]],
    "D21": [[0, 1], [0.01, 0]],
}


def _ac4() -> GeneralizedPlant:
    return GeneralizedPlant.from_matrices(**{k: np.array(v, float) for k, v in AC4.items()})


def _hand_sof(K: np.ndarray) -> tuple[np.ndarray, ...]:
    """The static-output-feedback closed loop written out by hand (D22 = 0)."""
    P = {k: np.array(v, float) for k, v in AC4.items()}
    return (P["A"] + P["B2"] @ K @ P["C2"], P["B1"] + P["B2"] @ K @ P["D21"],
            P["C1"] + P["D12"] @ K @ P["C2"], P["D11"] + P["D12"] @ K @ P["D21"])


def _fl_response(P: GeneralizedPlant, K: tuple, w: np.ndarray) -> np.ndarray:
    """F_l(P, K)(jw) = P11 + P12 K (I - P22 K)^-1 P21 from frequency responses (independent)."""
    Pss = (P.A, np.hstack([P.B1, P.B2]), np.vstack([P.C1, P.C2]),
           np.block([[P.D11, P.D12], [P.D21, P.D22]]))
    Pw = frequency_response(Pss, w)
    Kw = frequency_response(K, w)
    nz, nw = P.D11.shape
    out = []
    for Pi, Ki in zip(Pw, Kw, strict=True):
        P11, P12, P21, P22 = Pi[:nz, :nw], Pi[:nz, nw:], Pi[nz:, :nw], Pi[nz:, nw:]
        out.append(P11 + P12 @ Ki @ np.linalg.solve(np.eye(P22.shape[0]) - P22 @ Ki, P21))
    return np.array(out)


def test_sof_through_the_api_equals_the_hand_written_loop() -> None:
    P = _ac4()
    K = np.array([[-0.30048, -0.07271]])
    pb = lft_problem(P, StaticGain("K", 1, 2, plant=P))
    assert [p.name for p in pb.parameters] == ["K.K[0,0]", "K.K[0,1]"]
    api = pb.objective(K.ravel())
    hand = hinf_norm(_hand_sof(K)).value
    assert api == pytest.approx(hand, rel=1e-9)
    for a, b in zip(lft(P, K), _hand_sof(K), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_lft_with_d22_and_dynamic_controller_matches_frequency_responses() -> None:
    rng = np.random.default_rng(0)
    np.random.seed(0)
    G = control.rss(4, 5, 5)
    D = rng.standard_normal((5, 5)) * 0.3
    P = GeneralizedPlant.from_ss((G.A, G.B, G.C, D), ny=2, nu=2)
    assert P.dims == {"nx": 4, "nw": 3, "nu": 2, "nz": 3, "ny": 2}
    assert np.any(P.D22)
    Kc = control.rss(3, 2, 2)
    K = (Kc.A, Kc.B, Kc.C, rng.standard_normal((2, 2)) * 0.5)
    w = np.logspace(-2, 2, 30)
    cl = lft(P, K)
    np.testing.assert_allclose(frequency_response(cl, w), _fl_response(P, K, w), rtol=1e-9,
                               atol=1e-12)
    # a python-control LTI controller is accepted as well
    np.testing.assert_allclose(lft(P, control.ss(*K))[0], cl[0], atol=1e-12)


def test_ill_posed_and_shape_errors() -> None:
    P = GeneralizedPlant.from_matrices([[-1.0]], [[1.0]], [[1.0]], [[1.0]], [[1.0]], D22=[[1.0]])
    with pytest.raises(ValueError, match="ill-posed"):
        lft(P, np.array([[1.0]]))
    assert lft(P, np.array([[0.5]]))[0].shape == (1, 1)
    with pytest.raises(ValueError, match="controller must map"):
        lft(P, np.ones((2, 1)))
    with pytest.raises(ValueError, match="A must be square"):
        GeneralizedPlant.from_matrices(np.ones((2, 3)), [[1.0]], [[1.0]], [[1.0]], [[1.0]])
    with pytest.raises(ValueError, match="controller structure maps"):
        lft_problem(_ac4(), StaticGain("K", 2, 2))


def test_tune_sof_ac4_and_the_result_is_the_hand_written_norm() -> None:
    P = _ac4()
    pb = lft_problem(P, StaticGain("K", 1, 2, plant=P))
    seen: list[Progress] = []
    res = tune(pb, n_starts=2, seed=1, progress=seen.append)
    assert res.stable
    K = res.theta.reshape(1, 2)
    assert res.value == pytest.approx(hinf_norm(_hand_sof(K)).value, rel=1e-9)
    # the published SOF optimum for AC4 is ~0.9355 (hinfstruct); the start point gives more
    assert res.value < 0.94
    assert seen and all(math.isfinite(s.value) for s in seen)
    for a, b in itertools.pairwise(seen):
        if a.start == b.start:
            assert b.value <= a.value  # accepted steps decrease the objective


def test_random_starts_are_scaled_to_the_plant() -> None:
    P = _ac4()
    gs = P.gain_scale()
    blk = StaticGain("K", 1, 2, plant=P)
    prm = blk.parameters()
    np.testing.assert_allclose([p.sample_sd for p in prm], gs.ravel())
    np.testing.assert_allclose([p.upper for p in prm], 1e3 * gs.ravel())
    # entries scale with the plant: a 100x larger actuator gain gives 100x smaller gains
    P2 = GeneralizedPlant.from_matrices(P.A, P.B1, 100 * P.B2, P.C1, P.C2, P.D11, P.D12, P.D21)
    np.testing.assert_allclose(P2.gain_scale(), gs / 100)


def test_time_limit_interrupt_and_regularisation() -> None:
    P = _ac4()
    pb = lft_problem(P, StaticGain("K", 1, 2, plant=P))
    res = tune(pb, n_starts=50, seed=0, time_limit=0.5)
    assert "time limit reached" in res.message
    assert len(res.starts) < 51
    assert res.stable and res.value == pytest.approx(pb.objective(res.theta), rel=1e-12)

    calls = []

    def stop_after_two(p: Progress) -> None:
        calls.append(p)
        if len(calls) == 2:
            raise KeyboardInterrupt

    res = tune(pb, n_starts=3, seed=0, progress=stop_after_two)
    assert "interrupted" in res.message
    assert len(res.starts) == 1 and res.stable
    assert res.value == pytest.approx(calls[-1].value, rel=1e-12)

    rho = 1e-3
    reg = tune(pb, seed=0, regularization=rho)
    scales = np.array([p.typical for p in pb.parameters])
    pen = rho * float(np.sum((reg.theta / scales) ** 2))
    assert reg.value == pytest.approx(pb.objective(reg.theta) + pen, rel=1e-9)
    with pytest.raises(ValueError, match="time_limit"):
        tune(pb, time_limit=0.0)


def test_structure_of_blocks_and_ppid_equals_the_paper_loop() -> None:
    from vtolftc.synthesis.loops import PARAM_NAMES, closed_loop

    J = 0.05
    G = control.ss([[0.0, 0.0], [1.0, 0.0]], [[1 / J], [0.0]], np.eye(2), np.zeros((2, 1)))
    A, B = np.asarray(G.A), np.asarray(G.B)
    Cq, Cth = np.asarray(G.C)[[0]], np.asarray(G.C)[[1]]
    # w = [r, d], z = [e, u], y = [r - angle, rate], u = moment (plant sees u + d)
    P = GeneralizedPlant.from_matrices(
        A, np.hstack([np.zeros((2, 1)), B]), B, np.vstack([-Cth, np.zeros((1, 2))]),
        np.vstack([-Cth, Cq]), [[1.0, 0.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0], [0.0, 0.0]],
    )
    gains = dict(zip(PARAM_NAMES, (3.0, 0.4, 0.3, 0.01, 0.02), strict=True))
    st = ControllerStructure([PPIDBlock("att", gains)])
    th = np.array([gains[k] for k in PARAM_NAMES])
    cl = lft(P, st.realize(th))
    ref = closed_loop(G, th)
    w = np.logspace(-2, 3, 40)
    np.testing.assert_allclose(frequency_response(cl, w),
                               frequency_response((ref.A, ref.B, ref.C[:2], ref.D[:2]), w),
                               rtol=1e-9, atol=1e-12)
    # composition: a PID next to a static gain and a state-space block, shapes add up
    st2 = ControllerStructure(
        [PIDBlock("pid"), StaticGain("K", 2, 1), StateSpaceBlock("ss", 2, 1, 2)]
    )
    assert (st2.n_out, st2.n_in) == (4, 4)
    th2 = np.array([p.initial for p in st2.parameters()])
    Ak, Bk, Ck, Dk = st2.realize(th2)
    assert Ak.shape == (4, 4) and Bk.shape == (4, 4) and Ck.shape == (4, 4)
    assert Dk.shape == (4, 4)
    assert set(st2.split(th2)) == {"pid", "K", "ss"}
