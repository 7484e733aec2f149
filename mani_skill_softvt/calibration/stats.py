"""Calibration statistics as pure functions: slip, the gripper envelope and the tolerance.

Given sweep records ``{"closure", "held", "peak_deformation", "aperture_mm", ...}``:

- g_min: the loosest closure at which every repeat holds without slip;
- tau_o: the ``percentile``-th percentile of peak D over the stable grasps (held, g >= g_min);
- g_max: the tightest closure >= g_min at which every repeat holds and stays within tau_o.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from ..physics.transforms import quat_wxyz_to_matrix


def slip_distance(centroids: np.ndarray, tcp_positions: np.ndarray, tcp_quats_wxyz: np.ndarray) -> float:
    """Displacement (m) of the object relative to the hand between the first and last sample.

    The centroid is expressed in the TCP frame at each sample, so carrying the object does not
    count as slip; only its motion with respect to the fingers does.
    """
    c = np.asarray(centroids, np.float64)
    p = np.asarray(tcp_positions, np.float64)
    q = np.asarray(tcp_quats_wxyz, np.float64)
    if not (c.shape == p.shape and c.ndim == 2 and c.shape[1] == 3 and q.shape == (len(c), 4)) or len(c) < 2:
        raise ValueError(f"slip_distance needs matching (T>=2, 3) positions and (T, 4) quaternions, got "
                         f"{c.shape}, {p.shape}, {q.shape}")
    rel = [quat_wxyz_to_matrix(q[i]).T @ (c[i] - p[i]) for i in (0, -1)]
    return float(np.linalg.norm(rel[1] - rel[0]))


def by_closure(records: list[dict]) -> dict[float, list[dict]]:
    groups = defaultdict(list)
    for r in records:
        groups[round(float(r["closure"]), 6)].append(r)
    return dict(sorted(groups.items()))


def stable_grasps(records: list[dict]) -> tuple[float, list[dict]]:
    """g_min (the loosest closure where every repeat holds) and the stable grasps: the held trials
    at closures >= g_min. Raises ValueError when no closure holds in every repeat."""
    groups = by_closure(records)
    holding = [g for g, rs in groups.items() if all(r["held"] for r in rs)]
    if not holding:
        raise ValueError("no closure held in every repeat: widen the sweep towards tighter closures")
    g_min = holding[0]
    return g_min, [r for g, rs in groups.items() if g >= g_min for r in rs if r["held"]]


def gripper_envelope(records: list[dict], percentile: float = 90.0) -> dict:
    """g_min, g_max, tau_o and the apertures from sweep records (see the module docstring).

    Raises ValueError when no closure holds (the sweep never found a stable grasp).
    """
    if not records:
        raise ValueError("no sweep records")
    if not 0.0 < percentile <= 100.0:
        raise ValueError(f"percentile must be in (0, 100], got {percentile}")
    groups = by_closure(records)
    g_min, stable = stable_grasps(records)
    tau = float(np.percentile([r["peak_deformation"] for r in stable], percentile))
    within = [g for g, rs in groups.items()
              if g >= g_min and all(r["held"] and r["peak_deformation"] <= tau for r in rs)]
    # g_min always qualifies unless its own peaks exceed tau (then the envelope is that one point).
    g_max = within[-1] if within else g_min
    ap_min = float(np.mean([r["aperture_mm"] for r in groups[g_min]]))
    ap_max = float(np.mean([r["aperture_mm"] for r in groups[g_max]]))
    return {
        "g_min": g_min, "g_max": g_max, "tau_o": tau, "percentile": float(percentile),
        "aperture_g_min_mm": ap_min, "aperture_g_max_mm": ap_max, "span_mm": ap_min - ap_max,
        "n_stable": len(stable),
    }
