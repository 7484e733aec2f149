"""Pose conventions: the one place where quaternion orders are converted.

SAPIEN and ManiSkill store quaternions as (w, x, y, z); Warp and Newton as (x, y, z, w).
Poses travel as 7-vectors: SAPIEN order ``[px, py, pz, qw, qx, qy, qz]`` and Newton/Warp
transform order ``[px, py, pz, qx, qy, qz, qw]``.
"""

from __future__ import annotations

import numpy as np


def wxyz_to_xyzw(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q)
    return np.concatenate([q[..., 1:4], q[..., 0:1]], axis=-1)


def xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q)
    return np.concatenate([q[..., 3:4], q[..., 0:3]], axis=-1)


def sapien_pose_to_newton(pose7: np.ndarray) -> np.ndarray:
    """[p, q_wxyz] -> [p, q_xyzw] (Warp ``transform`` layout)."""
    pose7 = np.asarray(pose7, dtype=np.float64)
    return np.concatenate([pose7[..., :3], wxyz_to_xyzw(pose7[..., 3:7])], axis=-1)


def newton_pose_to_sapien(pose7: np.ndarray) -> np.ndarray:
    pose7 = np.asarray(pose7, dtype=np.float64)
    return np.concatenate([pose7[..., :3], xyzw_to_wxyz(pose7[..., 3:7])], axis=-1)


def quat_wxyz_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion in (w, x, y, z) order."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def pose_wxyz_to_matrix(pose7: np.ndarray) -> np.ndarray:
    """4x4 homogeneous matrix of a SAPIEN-order pose [p, q_wxyz]."""
    m = np.eye(4)
    m[:3, :3] = quat_wxyz_to_matrix(pose7[3:7])
    m[:3, 3] = pose7[:3]
    return m


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product a * b of two quaternions in (w, x, y, z) order."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def quat_conjugate(q) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion), (w, x, y, z) order."""
    return np.asarray(q, np.float64) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_angle(q1, q2) -> float:
    """Rotation angle (rad) between two unit quaternions (wxyz)."""
    d = abs(float(np.dot(np.asarray(q1) / np.linalg.norm(q1), np.asarray(q2) / np.linalg.norm(q2))))
    return float(2 * np.arccos(min(1.0, d)))


def quat_to_rotvec(q, reference=None) -> np.ndarray:
    """Axis-angle of a quaternion (wxyz); of its two representations near a half turn
    (theta * n and (theta - 2 pi) * n), the one closer to ``reference``, so that a stream of
    near-top-down orientations stays continuous."""
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q)
    if q[0] < 0:
        q = -q
    s = np.linalg.norm(q[1:])
    if s < 1e-12:
        return np.zeros(3)
    axis = q[1:] / s
    theta = 2 * np.arctan2(s, q[0])  # in [0, pi]
    r = theta * axis
    if reference is not None:
        alt = (theta - 2 * np.pi) * axis
        if np.linalg.norm(alt - reference) < np.linalg.norm(r - reference):
            r = alt
    return r


def rotvec_to_quat(r) -> np.ndarray:
    """Quaternion (wxyz) of an axis-angle ``r`` (the inverse of :func:`quat_to_rotvec` up to sign)."""
    r = np.asarray(r, np.float64)
    theta = float(np.linalg.norm(r))
    if theta < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(theta / 2)], np.sin(theta / 2) * r / theta])


# ---------------------------------------------------------------- the top-down hand
# Every scripted grasp holds the hand pointing straight down, turned by a yaw about world z:
# the rotation Rz(yaw) * Rx(pi), whose quaternion (w, x, y, z) is (0, cos(yaw/2), sin(yaw/2), 0).
def down_quat(yaw: float) -> np.ndarray:
    """Quaternion (wxyz) of the top-down hand turned by ``yaw`` about z: Rz(yaw) * Rx(pi)."""
    return np.array([0.0, np.cos(yaw / 2), np.sin(yaw / 2), 0.0])


def down_rotvec(yaw: float) -> np.ndarray:
    """Axis-angle of :func:`down_quat`: a half turn about (cos(yaw/2), sin(yaw/2), 0)."""
    return np.pi * np.array([np.cos(yaw / 2), np.sin(yaw / 2), 0.0])


def down_quat_yaw(q) -> float:
    """Yaw of a near-top-down hand quaternion (wxyz): its x axis projected on the table."""
    w, x, y, z = q
    return float(np.arctan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z)))


# ---------------------------------------------------------------- planar and batched motion
def planar_rigid_fit(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray]:
    """Least-squares 2-D rigid motion src -> dst (Kabsch; (M, 2) point sets, M >= 1).

    Returns (angle, shift): dst ~ R(angle) (src - mean(src)) + mean(src) + shift, i.e. a rotation
    about the source centroid by ``angle`` (rad, from +x towards +y) and the centroid's
    displacement. In 2-D the Kabsch SVD reduces to angle = atan2(sum a x b, sum a . b) over the
    centred point pairs, which is never a reflection.
    """
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 2 or len(src) == 0:
        raise ValueError(f"planar_rigid_fit needs two (M, 2) point sets of equal shape, got {src.shape} and {dst.shape}")
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - cs, dst - cd
    cross = float((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum())
    dot = float((a * b).sum())
    angle = float(np.arctan2(cross, dot)) if (cross or dot) else 0.0
    return angle, cd - cs


def yaw_between(rest_points: np.ndarray, points: np.ndarray) -> float:
    """Yaw (rad) about z that turns a body's rest points into its current points (least squares)."""
    return planar_rigid_fit(np.asarray(rest_points)[:, :2], np.asarray(points)[:, :2])[0]


def angular_velocity_xyzw(q0: np.ndarray, q1: np.ndarray, dt: float) -> np.ndarray:
    """World-frame angular velocity taking unit quaternions q0 -> q1 (xyzw, batched (n, 4)) in dt."""
    x0, y0, z0, w0 = (q0[:, i] for i in range(4))
    x1, y1, z1, w1 = (q1[:, i] for i in range(4))
    # dq = q1 * conj(q0)
    w = w1 * w0 + x1 * x0 + y1 * y0 + z1 * z0
    x = -w1 * x0 + x1 * w0 - y1 * z0 + z1 * y0
    y = -w1 * y0 + y1 * w0 - z1 * x0 + x1 * z0
    z = -w1 * z0 + z1 * w0 - x1 * y0 + y1 * x0
    sign = np.where(w < 0, -1.0, 1.0)  # shortest arc
    v = np.stack([x, y, z], axis=1) * sign[:, None]
    s = np.linalg.norm(v, axis=1)
    angle = 2.0 * np.arctan2(s, np.abs(w))
    axis = np.where(s[:, None] > 1e-12, v / np.maximum(s, 1e-12)[:, None], 0.0)
    return (axis * (angle / dt)[:, None]).astype(np.float32)
