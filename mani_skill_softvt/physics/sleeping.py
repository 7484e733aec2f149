"""When a soft body may skip simulation: pure functions of the sleep rule.

A resting soft body that nothing moving comes near costs the full FEM every tick (89 % of an
episode's wall time is the Newton tick) and changes nothing. Like PhysX's sleeping rigid bodies,
:class:`~mani_skill_softvt.physics.fem.SoftBodyWorld` then stops simulating it:

- a body falls asleep after ``SLEEP_TICKS`` consecutive ticks in which each of its nodes moved
  slower than ``SLEEP_SPEED`` and no disturbing collider was near (its velocities are then zeroed:
  at rest);
- a sleeping body's particles are inactive for VBD: not moved, not solved, and their contacts
  are not reported (only static supports touch a sleeping body, and they take no feedback);
- while every body sleeps, the tick is skipped altogether and the wrenches of the last simulated
  tick are returned (the steady contact, e.g. the weight on the table);
- a body wakes, and that tick is simulated, as soon as a disturbing collider's end-of-tick pose
  comes within ``wake_distance`` of its bounds: the contact gap plus the node radius plus a
  margin, so it is awake before any collider reaches the contact gap.

A collider disturbs when it is *movable* (the robot's links: they may push at any time) or when
it moved this tick; a static support (the table, a basket) touching the body does not. Each
collider is bounded by a sphere (centre in its own frame, radius), conservative for the check.
"""

from __future__ import annotations

import numpy as np

SLEEP_SPEED = 2e-4  # m/s: just above the ~0.15 mm/s node jitter of a resting body
SLEEP_TICKS = 24  # 0.1 s at 240 Hz: two control steps of quiet before sleeping
WAKE_MARGIN = 1e-2  # m: beyond the contact gap; a collider moves < 4 mm per tick even at 1 m/s


def bounding_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """A sphere around ``points`` (N, 3): centre of their box, radius to the farthest point."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    centre = 0.5 * (points.min(0) + points.max(0))
    return centre, float(np.linalg.norm(points - centre, axis=1).max())


def box_corners(half_extents, local_pose7_xyzw: np.ndarray) -> np.ndarray:
    """The 8 corners of a box with ``half_extents`` placed by ``local_pose7_xyzw`` (p, q xyzw)."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64)
    return rotate_xyzw(local_pose7_xyzw[3:7], signs * np.asarray(half_extents, np.float64)) + local_pose7_xyzw[:3]


def rotate_xyzw(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``q`` (..., 4) in xyzw order (Newton's)."""
    q = np.asarray(q, np.float64)
    v = np.asarray(v, np.float64)
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def sphere_box_distance(centres: np.ndarray, box_min: np.ndarray, box_max: np.ndarray) -> np.ndarray:
    """Distance from each centre (N, 3) to an axis-aligned box (0 inside)."""
    gap = np.maximum(box_min - centres, 0.0) + np.maximum(centres - box_max, 0.0)
    return np.linalg.norm(gap, axis=-1)


def colliders_near(collider_q: np.ndarray, centres_local: np.ndarray, radii: np.ndarray,
                   box_min: np.ndarray, box_max: np.ndarray, wake_distance: float) -> np.ndarray:
    """Which colliders' bounding spheres, posed by ``collider_q`` (N, 7: p, q xyzw), come within
    ``wake_distance`` of the box [box_min, box_max]."""
    centres = collider_q[:, :3] + rotate_xyzw(collider_q[:, 3:7], centres_local)
    return sphere_box_distance(centres, box_min, box_max) <= radii + wake_distance


def is_quiet(max_node_speed: float, disturbed: bool) -> bool:
    """A tick that counts towards falling asleep."""
    return not disturbed and max_node_speed < SLEEP_SPEED
