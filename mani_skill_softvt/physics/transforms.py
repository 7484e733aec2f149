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
