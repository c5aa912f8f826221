"""The one rotation module against independent answers (scipy's Rotation, finite products)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vtolftc.base.rotation import dcm, euler_to_quat, quat_mul, quat_to_euler
from vtolftc.firmware_sim.vehicle.dynamics import quat_to_dcm

rng = np.random.default_rng(7)
EULERS = [(float(r), float(p), float(y)) for r, p, y in zip(
    rng.uniform(-np.pi, np.pi, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-np.pi, np.pi, 50),
    strict=True)]


@pytest.mark.parametrize("e", EULERS[:10])
def test_euler_quat_against_scipy(e):
    q = euler_to_quat(*e)
    ref = Rotation.from_euler("ZYX", [e[2], e[1], e[0]]).as_quat(scalar_first=True)
    assert np.allclose(q, ref * np.sign(ref[0] * q[0]), atol=1e-14)
    assert np.allclose(quat_to_euler(q), e, atol=1e-12)


def test_dcm_against_scipy_and_the_compiled_copy():
    for e in EULERS:
        q = euler_to_quat(*e)
        R = dcm(q)
        assert np.allclose(R, Rotation.from_quat(q, scalar_first=True).as_matrix(), atol=1e-14)
        Rc = np.empty((3, 3))
        quat_to_dcm(*q.tolist(), Rc)
        assert np.array_equal(R, Rc)  # the vehicle's inlined copy: the same bits


def test_quat_mul_composes_rotations():
    for e1, e2 in zip(EULERS[:25], EULERS[25:], strict=True):
        a, b = euler_to_quat(*e1), euler_to_quat(*e2)
        assert np.allclose(dcm(quat_mul(a, b)), dcm(a) @ dcm(b), atol=1e-13)


def test_quat_to_euler_clips_at_gimbal_lock():
    q = np.array([np.sqrt(0.5), 0.0, np.sqrt(0.5) * (1 + 1e-15), 0.0])
    assert quat_to_euler(q)[1] == pytest.approx(np.pi / 2)
    assert quat_to_euler(list(q)) == quat_to_euler(q)
