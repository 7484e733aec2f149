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
collider is bounded by its shapes' box in its own frame, posed each tick and boxed again in the
world (conservative for the check; a sphere around the Panda hand, 11 cm in radius, woke the
object 16 control steps before the fingers touched it).
"""

from __future__ import annotations

import numpy as np

SLEEP_SPEED = 2e-4  # m/s: just above the ~0.15 mm/s node jitter of a resting body
SLEEP_TICKS = 24  # 0.1 s at 240 Hz: two control steps of quiet before sleeping
WAKE_MARGIN = 1e-2  # m: beyond the contact gap; a collider moves < 4 mm per tick even at 1 m/s


def local_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box around ``points`` (N, 3) in their own frame: (min corner, max corner)."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    return points.min(0), points.max(0)


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


def world_boxes(collider_q: np.ndarray, local_min: np.ndarray, local_max: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned world boxes (min, max: (N, 3)) around local boxes posed by ``collider_q``
    (N, 7: p, q xyzw). Each contains its collider's shapes, so distances from it are conservative."""
    signs = np.array([[sx, sy, sz] for sx in (0, 1) for sy in (0, 1) for sz in (0, 1)], np.float64)
    corners = local_min[:, None] + signs[None] * (local_max - local_min)[:, None]  # (N, 8, 3)
    world = rotate_xyzw(collider_q[:, None, 3:7], corners) + collider_q[:, None, :3]
    return world.min(1), world.max(1)


def box_gap(a_min: np.ndarray, a_max: np.ndarray, b_min: np.ndarray, b_max: np.ndarray) -> np.ndarray:
    """Distance between axis-aligned boxes a (N, 3 corners) and b (0 where they overlap)."""
    gap = np.maximum(b_min - a_max, 0.0) + np.maximum(a_min - b_max, 0.0)
    return np.linalg.norm(gap, axis=-1)


def is_quiet(max_node_speed: float, disturbed: bool) -> bool:
    """A tick that counts towards falling asleep."""
    return not disturbed and max_node_speed < SLEEP_SPEED
