"""The surface problems' shared realisation (:class:`SurfaceRealizer`) is the channel-by-
channel path it replaces, bit for bit (issue 23: the tuner's designs must not move)."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.airframe.loader import load_airframe
from vtolftc.synthesis.hinfnorm import StateSpaceData, as_state_space
from vtolftc.synthesis.robust import RobustMethod, robust_points
from vtolftc.synthesis.structured import TuningProblem, _Evaluator
from vtolftc.synthesis.surfaces import (
    SurfaceProblem,
    SurfaceRealizer,
    surface_grid,
    surface_problem,
)


def _problem(axis: str, degree: int = 2) -> SurfaceProblem:
    af = load_airframe()
    pts = robust_points(af)
    by_v = {p.airspeed_m_s: p for p in pts}
    grid = surface_grid([by_v[0.0], by_v[4.0], by_v[10.0]], 2)     # 0, 2, 4, 7, 10 m/s
    return surface_problem(RobustMethod(), af, axis, grid, degree)


def _reference(pb: TuningProblem, theta: np.ndarray) -> list[StateSpaceData]:
    return [as_state_space(c(theta)) for c in pb.channels]


@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
def test_realizer_is_the_channel_by_channel_path_bit_for_bit(axis: str) -> None:
    sp = _problem(axis)
    pb = sp.problem
    assert isinstance(pb.realizer, SurfaceRealizer)
    # one group (gains, closed loop) per grid point, the channels of that point in it
    groups = [sorted({sp.point_of_channel[i] for i in g}) for g in pb.realizer.groups]
    assert sorted(g[0] for g in groups) == list(range(len(sp.grid)))
    assert all(len(g) == 1 for g in groups)
    rng = np.random.default_rng(7)
    lo, hi, x0 = pb.lower, pb.upper, pb.initial
    span = np.where(np.isfinite(hi - lo), hi - lo, 10 * pb.scales)
    thetas = [x0] + [np.clip(x0 + s * span * rng.standard_normal(x0.size), lo, hi)
                     for s in (0.01, 0.1, 1.0, 1.0)]
    for theta in thetas:
        got, ref = pb.realize(theta), _reference(pb, theta)
        assert len(got) == len(ref)
        seen = set()
        for g, r in zip(got, ref, strict=True):
            for x, y in zip(g, r, strict=True):
                assert x.dtype == y.dtype == np.float64 and x.shape == y.shape
                assert x.tobytes() == y.tobytes()       # bit for bit, signs of zeros too
                assert id(x) not in seen                 # no array shared between channels
                seen.add(id(x))


def test_realizer_raises_as_the_checked_path_does_on_non_finite_data() -> None:
    pb = _problem("roll", 1).problem
    theta = pb.initial.copy()
    theta[0] = np.nan
    with pytest.raises(ValueError) as ref:
        _reference(pb, theta)
    with pytest.raises(ValueError) as got:
        pb.realize(theta)
    assert str(got.value) == str(ref.value)


def test_realizer_only_for_surface_channels_around_cascades() -> None:
    pb = _problem("pitch", 0).problem
    assert SurfaceRealizer.applies(pb.channels)
    assert not SurfaceRealizer.applies([c.inner for c in pb.channels])
    with pytest.raises(ValueError):
        SurfaceRealizer([c.inner for c in pb.channels])


@pytest.mark.parametrize("axis", ["roll", "yaw"])
def test_realizer_batch_is_each_channels_realize_batch_bit_for_bit(axis: str) -> None:
    pb = _problem(axis).problem
    assert pb.realizer is not None
    rng = np.random.default_rng(3)
    x0 = pb.initial
    thetas = x0 + 0.05 * pb.scales * rng.standard_normal((6, x0.size))
    got = pb.realizer.batch(thetas)
    for c, g in zip(pb.channels, got, strict=True):
        for x, y in zip(g, c.realize_batch(thetas), strict=True):
            assert x.shape == y.shape and x.tobytes() == y.tobytes()


def test_central_differences_and_abscissa_gradients_unchanged_by_the_realizer() -> None:
    """The tuner's derivative stacks and abscissa gradients with the realizer are those of
    the channel-by-channel problem (no realizer), bit for bit."""
    sp = _problem("yaw")
    pb = sp.problem
    plain = TuningProblem(pb.parameters, pb.channels, pb.channel_names,
                          pb.stability_margin)
    rng = np.random.default_rng(5)
    theta = pb.initial + 0.02 * pb.scales * rng.standard_normal(pb.initial.size)
    fast, slow = _Evaluator(pb), _Evaluator(plain)
    assert fast.chain_rule and not slow.chain_rule
    fast.chain_rule = False  # the realizer's batch of theta-differences, not the chain rule
    for s1, s2 in zip(fast.derivative_stacks(theta), slow.derivative_stacks(theta),
                      strict=True):
        for x, y in zip(s1, s2, strict=True):
            assert x.tobytes() == y.tobytes()
    v1, g1 = fast.abscissa_and_grad(theta)
    v2, g2 = slow.abscissa_and_grad(theta)
    assert v1.tobytes() == v2.tobytes()
    assert g1 is not None and g2 is not None
    # the gradient rows against the per-entry form they replace
    from vtolftc.synthesis.structured import _rightmost_eig

    ref = np.zeros_like(g1)
    for i, (A, _, _, _) in enumerate(slow.realize(theta)):
        _, y, x = _rightmost_eig(A)
        den = np.vdot(y, x)
        dAx = slow.derivative_stacks(theta)[i][0] @ x
        for k in range(ref.shape[1]):
            ref[i, k] = float(np.real(np.vdot(y, dAx[k]) / den))
    assert g1.tobytes() == ref.tobytes() == g2.tobytes()
