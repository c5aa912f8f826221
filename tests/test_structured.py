"""Tests of vtolftc.synthesis.structured (structured H-infinity tuning, paper eqs. 4-8)."""

from __future__ import annotations

import math
import warnings

import control
import numpy as np
import pytest

from vtolftc.synthesis.hinfnorm import hinf_norm
from vtolftc.synthesis.structured import (
    Parameter,
    TuningProblem,
    closed_loops,
    mixed_sensitivity,
    mixed_sensitivity_channel,
    pid,
    tune,
)

# paper-style weights: eq. 5 Ws = (s/M + wb)/(s + A wb), eq. 6 Wr = (r s + wa 1e-3)/(s + wa)
WS = control.tf([1 / 2.0, 1.0], [1.0, 1e-2])  # M = 2, wb = 1 rad/s, A = 0.01
WR_STATIC = control.tf([0.1], [1.0])


def _second_order_controller(th: np.ndarray) -> tuple[np.ndarray, ...]:
    """K(s) = (b2 s^2 + b1 s + b0) / (s^2 + a1 s + a0), controllable canonical form."""
    b2, b1, b0, a1, a0 = th
    A = np.array([[0.0, 1.0], [-a0, -a1]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[b0 - b2 * a0, b1 - b2 * a1]])
    D = np.array([[b2]])
    return A, B, C, D


def test_reaches_full_order_hinfsyn_optimum() -> None:
    """G = 1/(s+1), ||[Ws S; Wr R]||_inf: the optimal controller has order 2 (= order of the
    generalised plant), which the tuned structure contains, so gamma_opt is reachable."""
    G = control.tf([1.0], [1.0, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        P = control.augw(G, w1=WS, w2=WR_STATIC)
    K_opt, _, gamma_opt, _ = control.hinfsyn(P, 1, 1)
    assert K_opt.nstates == 2
    channel = mixed_sensitivity_channel(G, _second_order_controller, Ws=WS, Wr=WR_STATIC)
    problem = TuningProblem(
        [
            Parameter("b2", 0.0),
            Parameter("b1", 1.0),
            Parameter("b0", 1.0),
            Parameter("a1", 1.0),
            Parameter("a0", 0.1),
        ],
        [channel],
    )
    initial = problem.objective(problem.initial)
    res = tune(problem)
    assert res.stable
    assert res.value < initial
    assert res.value <= gamma_opt * 1.01
    assert res.value >= gamma_opt * (1 - 1e-6)
    # the reported value is the exact norm of the returned design
    assert hinf_norm(channel(res.theta)).value == pytest.approx(res.value, rel=1e-9)
    assert res.channel_values[0] == pytest.approx(res.value, rel=1e-9)


def _pid_problem() -> tuple[TuningProblem, float]:
    G = control.tf([2.0], [1.0, 1.5, 0.5])
    Ws = control.tf([1 / 2.0, 0.5], [1.0, 0.5e-3])
    Wr = control.tf([0.2, 5e-3], [1.0, 5.0])
    Wt = control.tf([1.0, 0.2], [0.02, 1.0])
    channel = mixed_sensitivity_channel(
        G, lambda th: pid(th[0], th[1], th[2], 0.01), Ws=Ws, Wt=Wt, Wr=Wr
    )
    problem = TuningProblem(
        [
            Parameter("kp", 1.0, lower=0.0),
            Parameter("ki", 0.5, lower=1e-6),
            Parameter("kd", 0.1, lower=0.0),
        ],
        [channel],
        channel_names=["nominal"],
    )
    return problem, problem.objective(problem.initial)


def test_pid_mixed_sensitivity_multistart_reproducible() -> None:
    problem, initial = _pid_problem()
    res = tune(problem, n_starts=3, seed=11)
    assert res.stable
    assert res.value <= initial
    assert len(res.starts) == 4
    assert all(r.history[0] >= r.history[-1] for r in res.starts if r.history)
    assert res.starts[0].history[0] == pytest.approx(initial)
    assert np.all(res.theta >= problem.lower)
    S, _, _ = closed_loops(
        control.tf([2.0], [1.0, 1.5, 0.5]), control.ss(*pid(*res.theta, 0.01))
    )
    assert np.all(S.poles().real < 0)
    again = tune(problem, n_starts=3, seed=11)
    np.testing.assert_array_equal(again.theta, res.theta)
    assert again.value == res.value
    assert set(res.params) == {"kp", "ki", "kd"}


def test_start_jobs_in_any_order_give_tune_bit_for_bit() -> None:
    """The starts as separate jobs (run in reverse order, records shuffled) combine into
    tune()'s result exactly: what the pipeline relies on to spread starts over workers."""
    from vtolftc.synthesis.structured import collect_starts, run_start, start_jobs

    problem, _ = _pid_problem()
    res = tune(problem, n_starts=3, seed=11)
    jobs = start_jobs(problem, n_starts=3, seed=11)
    assert [j[1] for j in jobs] == [0, 1, 2, 3]
    recs = [run_start(j) for j in reversed(jobs)]
    got = collect_starts(problem, recs)
    assert got.theta.tobytes() == res.theta.tobytes()
    assert got.value == res.value
    assert got.channel_values.tobytes() == res.channel_values.tobytes()
    assert [r.index for r in got.starts] == [0, 1, 2, 3]
    for a, b in zip(got.starts, res.starts, strict=True):
        assert a.theta.tobytes() == b.theta.tobytes() and a.history == b.history
    assert got.message == res.message
    with pytest.raises(ValueError, match="n_starts"):
        start_jobs(problem, n_starts=-1)


def test_unstable_initial_guess_is_stabilised() -> None:
    G = control.tf([1.0], [1.0, -1.0])  # open-loop unstable: needs kp > 1
    Ws = control.tf([1 / 2.0, 0.5], [1.0, 0.5e-3])
    Wr = control.tf([0.2, 5e-3], [1.0, 5.0])
    channel = mixed_sensitivity_channel(
        G, lambda th: pid(th[0], th[1], th[2], 0.01), Ws=Ws, Wr=Wr
    )
    problem = TuningProblem(
        [
            Parameter("kp", 0.1, lower=0.0),
            Parameter("ki", 0.1, lower=1e-6),
            Parameter("kd", 0.0, lower=0.0),
        ],
        [channel],
    )
    assert problem.objective(problem.initial) == math.inf
    res = tune(problem, n_starts=2, seed=0)
    assert res.stable and math.isfinite(res.value)
    assert res.value < 2.0  # a stabilising, reasonably tuned design (optimum ~0.70)
    # an unstabilisable structure is reported clearly, not silently
    bad = TuningProblem(
        [Parameter("kp", -0.5, upper=0.0), Parameter("ki", -0.1, upper=-1e-6)],
        [mixed_sensitivity_channel(G, lambda th: pid(th[0], th[1], 0.0, 0.01), Ws=Ws)],
    )
    res_bad = tune(bad)
    assert not res_bad.stable
    assert res_bad.value == math.inf
    assert "stabilising" in res_bad.message
    assert res_bad.starts[0].status.startswith("unstable")


def test_multi_model_channels_max() -> None:
    """Two design models (eq. 7-8 multi-model): the objective is the max of the channel
    norms; at the optimum both channels are active and the result beats a coarse grid."""
    Ws = control.tf([1 / 1.5, 2.0], [1.0, 2e-3])

    def ctrl(th: np.ndarray) -> tuple[np.ndarray, ...]:
        return pid(th[0], th[1], 0.0, 0.01)

    chans = [
        mixed_sensitivity_channel(control.tf([g], [1.0, 1.0]), ctrl, Ws=Ws, Wr=0.1)
        for g in (1.0, 3.0)
    ]
    problem = TuningProblem(
        [Parameter("kp", 1.0, lower=0.0), Parameter("ki", 1.0, lower=1e-6)], chans
    )
    grid_best = min(
        problem.objective(np.array([kp, ki]))
        for kp in np.linspace(0.5, 6.0, 12)
        for ki in np.linspace(0.5, 6.0, 12)
    )
    res = tune(problem)
    assert res.stable
    assert res.value == pytest.approx(max(res.channel_values), rel=1e-12)
    assert res.value <= grid_best
    assert res.channel_values[0] == pytest.approx(res.channel_values[1], rel=1e-3)


def test_mixed_sensitivity_matches_python_control() -> None:
    G = control.tf([2.0], [1.0, 1.5, 0.5])
    K = control.ss(*pid(1.0, 0.5, 0.1, 0.01))
    S, T, R = closed_loops(G, K)
    L = G * K
    w = np.array([0.1, 1.0, 10.0])
    for sys, ref in ((S, 1 / (1 + L)), (T, L / (1 + L)), (R, K / (1 + L))):
        np.testing.assert_allclose(
            sys(1j * w).reshape(-1), ref(1j * w).reshape(-1), rtol=1e-9
        )
    Wt = control.tf([1.0, 0.2], [0.02, 1.0])
    stack = mixed_sensitivity(G, K, Ws=WS, Wt=Wt, Wr=0.1)
    assert stack.noutputs == 3 and stack.ninputs == 1
    resp = stack(1j * w)
    np.testing.assert_allclose(resp[0, 0], (WS / (1 + L))(1j * w), rtol=1e-9)
    np.testing.assert_allclose(resp[1, 0], (Wt * L / (1 + L))(1j * w), rtol=1e-9)
    np.testing.assert_allclose(resp[2, 0], 0.1 * (K / (1 + L))(1j * w), rtol=1e-9)


def test_weight_and_input_validation() -> None:
    G = control.tf([1.0], [1.0, 1.0])
    K = control.ss(*pid(1.0, 0.5, 0.0, 0.01))
    with pytest.raises(ValueError, match="improper"):
        mixed_sensitivity(G, K, Wt=control.tf([1.0, 1.0], [1.0]))
    with pytest.raises(ValueError, match="integrator-like"):
        mixed_sensitivity(G, K, Ws=control.tf([0.5, 1.0], [1.0, 0.0]))
    with pytest.raises(ValueError, match="at least one"):
        mixed_sensitivity(G, K)
    with pytest.raises(ValueError, match="outside its bounds"):
        Parameter("kp", -1.0, lower=0.0)
    with pytest.raises(ValueError, match="theta has"):
        TuningProblem([Parameter("a", 1.0)], [lambda th: (np.eye(1), np.eye(1), np.eye(1),
                                                          np.zeros((1, 1)))]).objective([1, 2])
    with pytest.raises(ValueError, match="tf must be > 0"):
        pid(1.0, 1.0, 1.0, 0.0)
