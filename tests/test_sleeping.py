"""Sleeping soft bodies: the rule's geometry, and a resting cube that sleeps, stays put, and wakes
before an approaching collider reaches the contact gap; save/restore stays bit for bit."""

import numpy as np
import pytest

from mani_skill_softvt.assets.tetmesh import box_tetmesh
from mani_skill_softvt.physics.config import DEFAULT_PHYSICS
from mani_skill_softvt.physics.fem import SoftBodyWorld, SoftMaterial
from mani_skill_softvt.physics.sleeping import (SLEEP_TICKS, box_corners, box_gap, local_bounds,
                                                rotate_xyzw, world_boxes)
from mani_skill_softvt.physics.transforms import quat_wxyz_to_matrix

L = 0.05
PUSHER_HALF = np.array([0.01, 0.01, 0.01])


def test_rotation_matches_the_matrix_and_boxes_are_bounded():
    rng = np.random.default_rng(0)
    q_wxyz = rng.normal(size=(5, 4))
    q_wxyz /= np.linalg.norm(q_wxyz, axis=1, keepdims=True)
    v = rng.normal(size=(5, 3))
    expected = np.einsum("nij,nj->ni", np.stack([quat_wxyz_to_matrix(q) for q in q_wxyz]), v)
    assert np.allclose(rotate_xyzw(q_wxyz[:, [1, 2, 3, 0]], v), expected, atol=1e-12)
    corners = box_corners([0.1, 0.2, 0.3], np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0]))
    assert np.allclose(corners.min(0), [0.9, 1.8, 2.7]) and np.allclose(corners.max(0), [1.1, 2.2, 3.3])
    lo, hi = local_bounds(corners)
    assert np.allclose(lo, [0.9, 1.8, 2.7]) and np.allclose(hi, [1.1, 2.2, 3.3])


def test_world_boxes_contain_the_posed_shape_and_distances_are_exact():
    rng = np.random.default_rng(1)
    lo, hi = np.array([[-0.1, -0.02, 0.0]]), np.array([[0.1, 0.02, 0.05]])
    q = rng.normal(size=4)
    pose = np.concatenate([[0.3, -0.2, 0.5], q / np.linalg.norm(q)])[None]
    w_min, w_max = world_boxes(pose, lo, hi)
    pts = rng.uniform(lo, hi, size=(500, 3))  # points of the shape, posed
    posed = rotate_xyzw(pose[0, 3:], pts) + pose[0, :3]
    assert np.all(posed >= w_min - 1e-12) and np.all(posed <= w_max + 1e-12)
    # Gaps between unit boxes: overlapping, 1 m apart along x, sqrt(2) m apart diagonally.
    a_min = np.array([[0.5, 0.5, 0.5], [2.0, 0.0, 0.0], [2.0, 2.0, 0.0]])
    assert np.allclose(box_gap(a_min, a_min + 1.0, np.zeros(3), np.ones(3)), [0.0, 1.0, np.sqrt(2)])
    # A 0.2 m cube collider 1.5 m and 0.2 m from the unit box: only the second is within 0.3 m.
    q = np.array([[2.6, 0.5, 0.5, 0, 0, 0, 1], [1.3, 0.5, 0.5, 0, 0, 0, 1]])
    near = box_gap(*world_boxes(q, np.full((2, 3), -0.1), np.full((2, 3), 0.1)), np.zeros(3), np.ones(3)) <= 0.3
    assert near.tolist() == [False, True]


def _resting_cube_world():
    v, t = box_tetmesh((L, L, L), 6)
    w = SoftBodyWorld(sleeping=True)
    w.add_soft_body("cube", v, t, SoftMaterial(youngs_modulus=5e4, poisson_ratio=0.3, density=300.0, friction=1.0),
                    pose=np.array([0.0, 0.0, DEFAULT_PHYSICS.particle_radius, 1, 0, 0, 0]))
    w.add_collider_box("table", (0.2, 0.2, 0.01), local_pose=np.array([0, 0, -0.01, 1, 0, 0, 0]), friction=0.6)
    w.add_collider_box("pusher", PUSHER_HALF, movable=True)
    w.finalize()
    return w


def _poses(pusher_z: float) -> np.ndarray:
    return np.array([[0, 0, 0, 1, 0, 0, 0], [0, 0, pusher_z, 1, 0, 0, 0]], float)


def test_a_resting_cube_sleeps_stays_put_and_wakes_before_contact():
    w = _resting_cube_world()
    far = 0.3
    w.reset_collider_poses(_poses(far))
    ticks = 0
    while not w.asleep:  # settles under gravity on the table, then falls asleep
        last_awake = w.step()
        ticks += 1
        assert ticks < 2 * 240, "a resting cube should fall asleep within 2 s"
    assert ticks >= SLEEP_TICKS
    resting = w.particle_q()
    simulated = w.sleep_stats["ticks_simulated"]
    for _ in range(48):  # 0.2 s asleep: nothing is simulated, nothing moves
        wrench = w.step()
    assert w.sleep_stats["ticks_simulated"] == simulated and np.array_equal(w.particle_q(), resting)
    # Asleep it still presses on the table: the steady contact of its last simulated tick.
    assert np.array_equal(wrench, last_awake) and wrench[0, 2] < 0.0 and not np.any(wrench[1])

    # A movable pusher comes down at 0.1 m/s: the cube must be awake before the pusher's face
    # is within the contact gap of its top nodes, and the pusher then feels the contact.
    top = resting[:, 2].max()
    z, woke_at = far, None
    while z > top + PUSHER_HALF[2] - 2e-3:
        z -= 0.1 / 240
        w.set_collider_poses(_poses(z))
        wrench = w.step()
        if woke_at is None and not w.asleep:
            woke_at = z
    assert woke_at is not None
    clearance = woke_at - PUSHER_HALF[2] - top
    assert clearance > w.contact_gap + w.particle_radius, clearance
    assert wrench[1, 2] > 0.0  # 2 mm into the cube: the pusher is pushed back up


def test_each_body_sleeps_on_its_own():
    """Two cubes 30 cm apart: pushing one wakes it alone; the other stays asleep and bit-identical."""
    v, t = box_tetmesh((L, L, L), 6)
    w = SoftBodyWorld(sleeping=True)
    material = SoftMaterial(youngs_modulus=5e4, poisson_ratio=0.3, density=300.0, friction=1.0)
    for name, x in (("pushed", 0.0), ("bystander", 0.3)):
        w.add_soft_body(name, v, t, material, pose=np.array([x, 0.0, DEFAULT_PHYSICS.particle_radius, 1, 0, 0, 0]))
    w.add_collider_box("table", (0.5, 0.5, 0.01), local_pose=np.array([0, 0, -0.01, 1, 0, 0, 0]), friction=0.6)
    w.add_collider_box("pusher", PUSHER_HALF, movable=True)
    w.finalize()
    w.reset_collider_poses(_poses(0.3))
    while not w.asleep:
        w.step()
    bystander = w.particle_q(1)
    top = w.particle_q(0)[:, 2].max()
    for i in range(120):  # down onto the first cube, 2 mm into it
        w.set_collider_poses(_poses(top + PUSHER_HALF[2] + 0.05 - 0.052 * min(1.0, i / 100)))
        wrench = w.step()
    assert w.bodies_asleep().tolist() == [False, True]
    assert np.array_equal(w.particle_q(1), bystander) and not np.any(w.particle_qd(1))
    assert wrench[1, 2] > 0.0 and w.particle_q(0)[:, 2].max() < top  # the pushed cube is compressed


def test_save_restore_across_sleep_and_wake_is_bit_for_bit():
    w = _resting_cube_world()
    w.reset_collider_poses(_poses(0.3))
    while not w.asleep:
        w.step()
    saved = w.get_state()
    top = w.particle_q()[:, 2].max()

    def approach():
        out = []
        for i in range(120):  # from 5 cm above the top face down into contact
            w.set_collider_poses(_poses(top + PUSHER_HALF[2] + 0.05 - 0.06 * i / 119))
            out.append(np.concatenate([w.step().ravel(), w.particle_q().ravel(), [float(w.asleep)]]))
        return np.stack(out)

    first = approach()
    w.set_state(saved)
    assert w.asleep
    assert np.array_equal(approach(), first)


# The awake FEM lets a resting object creep sideways (VBD's smoothed Coulomb friction has no
# true stiction below FRICTION_EPSILON: 0.024 mm/s at 1e-4 m/s); asleep it does not. The expert
# then grasps a spot a few hundredths of a millimetre away, and R_max moves by that much: the
# issue's bound, 1e-3, holds for this task (docs/physics.md, for all ten).
SLEEP_R_MAX_TOLERANCE = 1e-3


@pytest.mark.slow  # two expert episodes (~50 s)
def test_an_expert_episode_scores_the_same_with_sleeping():
    from mani_skill_softvt.data.seeds import id_seed
    from mani_skill_softvt.evaluation.policies import ScriptedExpertPolicy
    from mani_skill_softvt.evaluation.runner import run_episode
    from mani_skill_softvt.evaluation.wrapper import make_env

    ep = {"suite": "object_soft", "task_id": 3, "condition": "id", "seed": id_seed(3, 0)}
    records, stats = {}, {}
    for sleep in (True, False):
        env = make_env("object_soft", 3, obs_mode="state_dict", control_mode="pd_ee_pose", soft_sleep=sleep)
        records[sleep] = run_episode(env, ScriptedExpertPolicy(), ep)
        stats[sleep] = dict(env.unwrapped.soft_world_stats)
        env.close()
    assert records[True]["termination"] == records[False]["termination"] == "success"
    assert abs(records[True]["r_max"] - records[False]["r_max"]) <= SLEEP_R_MAX_TOLERANCE
    assert stats[True]["ticks_asleep"] > 0 and stats[False]["ticks_asleep"] == 0
