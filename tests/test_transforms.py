"""Rotation helpers (physics.transforms): each against an independent construction."""

import numpy as np
import pytest

from mani_skill_softvt.physics.transforms import (angular_velocity_xyzw, down_quat, down_quat_yaw, down_rotvec,
                                                  planar_rigid_fit, quat_angle, quat_conjugate, quat_multiply,
                                                  quat_to_rotvec, quat_wxyz_to_matrix, wxyz_to_xyzw, yaw_between)


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _random_quat(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def test_product_and_conjugate_compose_rotation_matrices():
    rng = np.random.default_rng(0)
    for _ in range(20):
        a, b = _random_quat(rng), _random_quat(rng)
        np.testing.assert_allclose(quat_wxyz_to_matrix(quat_multiply(a, b)),
                                   quat_wxyz_to_matrix(a) @ quat_wxyz_to_matrix(b), atol=1e-12)
        np.testing.assert_allclose(quat_wxyz_to_matrix(quat_conjugate(a)), quat_wxyz_to_matrix(a).T, atol=1e-12)
        assert quat_angle(a, a) == pytest.approx(0.0, abs=1e-6)


def test_rotvec_rotates_like_its_quaternion():
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = _random_quat(rng)
        r = quat_to_rotvec(q)
        angle = np.linalg.norm(r)
        k = r / angle
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        rodrigues = np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx
        np.testing.assert_allclose(rodrigues, quat_wxyz_to_matrix(q), atol=1e-9)


@pytest.mark.parametrize("yaw", [-1.2, 0.0, 0.4, 1.5])
def test_top_down_hand_points_down_and_turns_by_its_yaw(yaw):
    m = quat_wxyz_to_matrix(down_quat(yaw))
    np.testing.assert_allclose(m[:, 2], [0, 0, -1], atol=1e-12)  # the fingers point at the table
    np.testing.assert_allclose(m[:2, 0], [np.cos(yaw), np.sin(yaw)], atol=1e-12)
    assert down_quat_yaw(down_quat(yaw)) == pytest.approx(yaw)
    # The axis-angle of the same rotation (one of its two representations at a half turn).
    np.testing.assert_allclose(quat_to_rotvec(down_quat(yaw), reference=down_rotvec(yaw)), down_rotvec(yaw), atol=1e-9)


def test_planar_fit_recovers_a_turn_and_a_shift():
    rng = np.random.default_rng(2)
    pts = rng.normal(size=(30, 3))
    moved = (pts - pts.mean(0)) @ _rot_z(0.3).T + pts.mean(0) + [0.1, -0.2, 0.0]
    angle, shift = planar_rigid_fit(pts[:, :2], moved[:, :2])
    assert angle == pytest.approx(0.3) and shift == pytest.approx([0.1, -0.2])
    assert yaw_between(pts, moved) == pytest.approx(0.3)


def test_angular_velocity_of_a_known_spin():
    dt, omega = 1 / 240, np.array([0.5, -1.0, 2.0])
    angle = np.linalg.norm(omega) * dt
    axis = omega / np.linalg.norm(omega)
    dq = np.array([np.cos(angle / 2), *(np.sin(angle / 2) * axis)])
    q0 = _random_quat(np.random.default_rng(3))
    q1 = quat_multiply(dq, q0)  # world-frame spin: q1 = dq * q0
    w = angular_velocity_xyzw(wxyz_to_xyzw(q0)[None], wxyz_to_xyzw(q1)[None], dt)[0]
    np.testing.assert_allclose(w, omega, rtol=1e-4)


def test_rotvec_to_quat_inverts_quat_to_rotvec():
    from mani_skill_softvt.physics.transforms import rotvec_to_quat

    rng = np.random.default_rng(2)
    for _ in range(20):
        q = _random_quat(rng)
        back = rotvec_to_quat(quat_to_rotvec(q))
        assert quat_angle(back, q) < 1e-7
    np.testing.assert_array_equal(rotvec_to_quat(np.zeros(3)), [1.0, 0.0, 0.0, 0.0])
    # The half-turn branch (theta - 2 pi) n is the same rotation.
    assert quat_angle(rotvec_to_quat(down_rotvec(0.3) - 2 * np.pi * down_rotvec(0.3) / np.pi), down_quat(0.3)) < 1e-7
