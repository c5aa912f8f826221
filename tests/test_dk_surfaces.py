"""D-K iteration on gain surfaces (``synthesis/dk_surfaces.py``), on a tiny problem: a
rate-and-angle cascade whose inertia grows with airspeed at three grid airspeeds, an
effectiveness cover Wt, Ws and Wr as in the robust design (no airframe, so it is fast).

How each test can fail (each was checked by breaking the code):

- the K-step test recomputes max_i ||D_i N_i D_i^-1|| / f_i with :func:`scaled_system`
  independently and fails if a K step ends above its start or does not start from the
  current surface (checked: a K step started from the parameters' initial gains reports
  12.49 where the current surface gives 1.64, and the test fails);
- the GS-SHIF test fails if GS-SHIF does not start from the SHIF result bit for bit (its
  iteration 0 must measure exactly SHIF's M) or ends above it (checked: GS-SHIF started from
  the starting constant instead fails on its iteration-0 gains);
- the D-scaling test fails if the D scaling is dropped (every D_i = 1: the K step then
  minimises the unscaled ||N_i||, and M equals the unscaled run's, 3.002, instead of 1.64:
  checked, the test fails).
"""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from vtolftc.synthesis.dk import cascade_rp, scaled_system
from vtolftc.synthesis.dk_surfaces import (
    GridModel,
    SurfaceDKProblem,
    SurfaceDKSettings,
    dk_surface,
    dk_surfaces,
)
from vtolftc.synthesis.hinfnorm import hinf_norm
from vtolftc.synthesis.loops import ControlWeight, SensitivityWeight
from vtolftc.synthesis.structured import Parameter
from vtolftc.synthesis.uncertainty import DesignPoint

START = {"kp_angle": 2.0, "kp_rate": 0.3, "ki_rate": 0.3, "kd_rate": 0.005, "tf_rate_s": 0.02}
SETTINGS = SurfaceDKSettings(max_iter=2, order=1, tune_iter=8, n_omegas=41)


def _problem() -> SurfaceDKProblem:
    """Three grid airspeeds (0, 5, 10 m/s), inertia 0.1, 0.2, 0.3 kg m^2 [N m s^2/rad]."""
    tau = 0.05
    models = []
    for i, (v, J) in enumerate(((0.0, 0.1), (5.0, 0.2), (10.0, 0.3))):
        G = ct.ss(ct.tf([1.0], [tau, 1.0])) * ct.ss([[0.0, 0.0], [1.0, 0.0]],
                                                    [[1.0 / J], [0.0]], np.eye(2),
                                                    np.zeros((2, 1)))
        Wt = ct.tf([2.0 / 20.0, 0.3], [1.0 / 20.0 / 6.0, 1.0])
        rp = cascade_rp(ct.ss(G), SensitivityWeight(1.5, 2.0), Wt,
                        ControlWeight(0.5, 2.0 * J / 0.1, 5.0))
        models.append(GridModel(DesignPoint(101 + i, v, max(0.0, v - 2.5), v + 2.5), rp, [],
                                1.0, None))
    params = [Parameter("kp_angle", 2.0, 0.1, 10.0, scale=1.0),
              Parameter("kp_rate", 0.3, 0.01, 3.0, scale=0.1),
              Parameter("ki_rate", 0.3, 0.001, 10.0, scale=0.1),
              Parameter("kd_rate", 0.005, 0.0, 0.05, scale=0.001),
              Parameter("tf_rate_s", 0.02, 0.01, 0.5, scale=0.02)]
    return SurfaceDKProblem("roll", models, params)


@pytest.fixture(scope="module")
def designs():  # type: ignore[no-untyped-def]
    pb = _problem()
    shif, gs = dk_surfaces(pb, START, 1, SETTINGS)
    return pb, shif, gs


def _worst_scaled(pb: SurfaceDKProblem, surface, scalings) -> float:  # type: ignore[no-untyped-def]
    K = surface.gain_matrix(pb.airspeeds_m_s)
    return max(hinf_norm(scaled_system(m.rp(K[i]), D)).value / m.floor
               for i, (m, D) in enumerate(zip(pb.models, scalings, strict=True)))


def test_k_step_never_increases_the_worst_scaled_norm(designs) -> None:  # type: ignore[no-untyped-def]
    pb, shif, gs = designs
    for res in (shif, gs):
        for prev, step in zip(res.steps, res.steps[1:], strict=False):
            before = _worst_scaled(pb, prev.surface, step.scalings)
            after = _worst_scaled(pb, step.surface, step.scalings)
            assert step.scaled_before == pytest.approx(before, rel=1e-6)
            assert step.scaled_after == pytest.approx(after, rel=1e-6)
            assert after <= before * (1 + 1e-9)
        assert res.measured <= res.steps[0].measured
    assert shif.measured < 0.97 * shif.steps[0].measured      # the iteration does something


def test_gs_shif_starts_at_shif_and_never_ends_above_it(designs) -> None:  # type: ignore[no-untyped-def]
    pb, shif, gs = designs
    assert shif.surface.basis.degree == 0 and gs.surface.basis.degree == 1
    vs = pb.airspeeds_m_s
    assert np.array_equal(gs.steps[0].surface.gain_matrix(vs), shif.surface.gain_matrix(vs))
    assert gs.steps[0].measured == shif.measured
    assert gs.measured <= shif.measured


def test_d_scaling_lowers_the_measured_worst_mu(designs) -> None:  # type: ignore[no-untyped-def]
    pb, shif, _ = designs
    plain = dk_surface(pb, pb.constant(START), SurfaceDKSettings(
        max_iter=SETTINGS.max_iter, order=SETTINGS.order, tune_iter=SETTINGS.tune_iter,
        n_omegas=SETTINGS.n_omegas, scaled=False))
    assert all(D.gain == 1.0 and D.order == 0 for s in plain.steps[1:] for D in s.scalings)
    assert shif.measured < 0.97 * plain.measured


def test_dk_surface_rejects_bad_settings_and_unstable_starts() -> None:
    pb = _problem()
    with pytest.raises(ValueError, match="max_iter"):
        dk_surface(pb, pb.constant(START), SurfaceDKSettings(max_iter=0))
    with pytest.raises(ValueError, match="degree"):
        dk_surfaces(pb, START, 0, SETTINGS)
    bad = dict(START, kp_rate=0.01, ki_rate=10.0)
    with pytest.raises(ValueError, match="stabilise"):
        dk_surface(pb, pb.constant(bad), SETTINGS)
