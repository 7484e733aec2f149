"""The deformation metric D_t (paper section 4.2) against analytic values."""

import numpy as np
import pytest

from mani_skill_softvt.physics.deformation import (
    bbox_diagonal,
    deformation,
    kabsch,
)
from mani_skill_softvt.physics.transforms import (
    newton_pose_to_sapien,
    quat_wxyz_to_matrix,
    sapien_pose_to_newton,
    wxyz_to_xyzw,
    xyzw_to_wxyz,
)


def _random_rotation(rng):
    q = rng.normal(size=4)
    return quat_wxyz_to_matrix(q / np.linalg.norm(q))


@pytest.fixture
def nodes():
    rng = np.random.default_rng(0)
    return rng.uniform(-0.03, 0.03, size=(200, 3)) + np.array([0.1, -0.2, 0.05])


def test_rigid_motion_gives_zero_deformation(nodes):
    rng = np.random.default_rng(1)
    for _ in range(5):
        r = _random_rotation(rng)
        moved = nodes @ r.T + rng.normal(size=3)
        # float64 round-off of a rotation of ~0.3 m coordinates: ~1e-16 relative
        assert deformation(moved, nodes) < 1e-13


def test_kabsch_recovers_rotation_and_never_reflects(nodes):
    rng = np.random.default_rng(2)
    r = _random_rotation(rng)
    t = np.array([0.3, -0.1, 0.2])
    r_est, t_est = kabsch(nodes, nodes @ r.T + t)
    np.testing.assert_allclose(r_est, r, atol=1e-12)
    np.testing.assert_allclose(t_est, t, atol=1e-12)
    mirrored = nodes * np.array([1.0, 1.0, -1.0])
    r_m, _ = kabsch(nodes, mirrored)
    assert np.linalg.det(r_m) == pytest.approx(1.0)


def test_affine_stretch_gives_analytic_rms():
    # A box grid (diagonal covariance C) stretched by a diagonal S: S C is symmetric positive
    # definite, so the best rotation is the identity (polar decomposition) and
    # D = RMS |(S - I)(x - c)| / diag(AABB(x_0)).
    g = np.linspace(-0.025, 0.025, 7)
    nodes = np.stack(np.meshgrid(g, g * 0.8, g * 1.2, indexing="ij"), axis=-1).reshape(-1, 3) + [0.1, 0.0, 0.04]
    s = np.diag([1.04, 0.98, 0.95])
    c = nodes.mean(axis=0)
    deformed = c + (nodes - c) @ s.T
    expected = np.sqrt(np.mean(np.sum(((nodes - c) @ (s - np.eye(3)).T) ** 2, axis=1))) / bbox_diagonal(nodes)
    assert deformation(deformed, nodes) == pytest.approx(expected, rel=1e-9)
    # ... and a rigid motion on top changes nothing.
    r = _random_rotation(np.random.default_rng(3))
    assert deformation(deformed @ r.T + 1.0, nodes) == pytest.approx(expected, rel=1e-9)


def test_nan_nodes_are_reported(nodes):
    bad = nodes.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        deformation(bad, nodes)


def test_quaternion_conventions_round_trip():
    q_wxyz = np.array([0.9, 0.1, -0.3, 0.2])
    assert np.array_equal(xyzw_to_wxyz(wxyz_to_xyzw(q_wxyz)), q_wxyz)
    assert np.array_equal(wxyz_to_xyzw(q_wxyz), [0.1, -0.3, 0.2, 0.9])
    pose = np.array([1.0, 2.0, 3.0, *q_wxyz])
    np.testing.assert_array_equal(newton_pose_to_sapien(sapien_pose_to_newton(pose)), pose)
    # A 90 deg rotation about z maps x to y.
    rz = quat_wxyz_to_matrix(np.array([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]))
    np.testing.assert_allclose(rz @ [1, 0, 0], [0, 1, 0], atol=1e-12)
