"""The deformation metric of SoftVTBench (paper section 4.2), as pure functions.

D_t = RMS_i || R x_t,i + t - x_0,i ||  /  diag(AABB(x_0))

where (R, t) is the best rigid transform aligning the current FEM nodes x_t to the settled
nodes x_0 (Kabsch). Removing rigid motion separates *being carried* from *being squeezed*;
dividing by the bounding-box diagonal makes objects of different size comparable.

R_t = D_t / tau_o and R_max = max_t R_t, with tau_o the object's calibrated tolerance, are the
benchmark's metrics (:mod:`mani_skill_softvt.evaluation.metrics`).
"""

from __future__ import annotations

import numpy as np


def kabsch(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best rigid transform (R, t), proper rotation, minimising sum ||R @ source_i + t - target_i||^2."""
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ValueError(f"kabsch needs two (N, 3) arrays of equal shape, got {source.shape} and {target.shape}")
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    h = (source - cs).T @ (target - ct)
    u, _, vt = np.linalg.svd(h)
    # Reflection guard: flip the last singular direction so det(R) = +1.
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, ct - r @ cs


def bbox_diagonal(points: np.ndarray) -> float:
    """Length of the diagonal of the axis-aligned bounding box of ``points`` (N, 3)."""
    points = np.asarray(points, dtype=np.float64)
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def rigid_aligned_rms(x_t: np.ndarray, x_0: np.ndarray) -> float:
    """RMS nodal distance between x_0 and x_t after removing the best rigid motion (metres)."""
    r, t = kabsch(x_t, x_0)
    aligned = np.asarray(x_t, dtype=np.float64) @ r.T + t
    return float(np.sqrt(np.mean(np.sum((aligned - np.asarray(x_0, dtype=np.float64)) ** 2, axis=1))))


def deformation(x_t: np.ndarray, x_0: np.ndarray) -> float:
    """Normalised deformation D_t (dimensionless): rigid-aligned RMS over the AABB diagonal of x_0."""
    x_0 = np.asarray(x_0, dtype=np.float64)
    if not np.all(np.isfinite(x_t)):
        raise ValueError("deformation: node positions contain NaN or inf (the simulation diverged)")
    return rigid_aligned_rms(x_t, x_0) / bbox_diagonal(x_0)
