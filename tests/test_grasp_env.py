"""The coupled SAPIEN + Newton scene: a Panda grasps, lifts and holds a soft cube.

One scripted episode is shared by the assertions (it costs ~30 s of CPU).
"""

import gymnasium as gym
import numpy as np
import pytest

import mani_skill_softvt.tasks  # noqa: F401
from mani_skill_softvt.expert.grasp_script import GraspPlan, run_grasp_script
from mani_skill_softvt.contracts.actions import ee_action
from mani_skill_softvt.tasks import constants as C


@pytest.fixture(scope="module")
def env():
    e = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose")
    yield e
    e.close()


@pytest.fixture(scope="module")
def episode(env):
    env.reset(seed=0)
    plan = GraspPlan()
    plan.steps = {**plan.steps, "lower": 0, "open": 0, "retreat": 0}
    return run_grasp_script(env, plan)


def test_settled_cube_rests_on_the_table(env):
    env.reset(seed=1)
    u = env.unwrapped
    assert u.settle_info["settled"]
    nodes = u.soft_nodes()
    # Bottom nodes sit one contact radius above the table top (z = 0), within 0.2 mm.
    assert nodes[:, 2].min() == pytest.approx(1e-3, abs=2e-4)


def test_grasp_lifts_at_least_9cm_and_holds_2s(episode):
    hold = episode["phase"] == "hold"
    assert hold.sum() >= 2 * C.CONTROL_FREQ
    assert episode["object_min_z"][hold].min() >= 0.09
    rel = episode["object_centroid"][hold] - episode["tcp"][hold]
    slip = np.linalg.norm(rel[-1] - rel[0])
    print(f"lift {episode['object_min_z'][hold].min()*1e3:.1f} mm, slip over hold {slip*1e3:.2f} mm")
    assert slip < 2e-3


def test_force_limited_close_stops_where_the_object_pushes_back(episode):
    hold = episode["phase"] == "hold"
    width = episode["gripper_width"][hold]
    force = episode["pad_force"][hold]
    print(f"jaw gap {width.mean()*1e3:.1f} mm, pad force {force.mean():.1f} N, D {episode['deformation'].max():.4f}")
    # The close command targets a negative gap; the cube keeps the jaws apart...
    assert width.min() > 0.02
    # ... and pushes back with about the drive's force limit (the drive saturates).
    assert force.mean() == pytest.approx(C.GRIPPER_FORCE_LIMIT, rel=0.2)
    assert 0.0 < episode["deformation"].max() < 0.2


def test_same_seed_same_initial_state(env):
    env.reset(seed=7)
    a = env.unwrapped.soft_nodes().copy()
    env.reset(seed=8)
    env.reset(seed=7)
    assert np.array_equal(a, env.unwrapped.soft_nodes())


def test_env_state_restore_replays_bit_for_bit(env):
    env.reset(seed=3)
    u = env.unwrapped
    xy = u.soft_nodes().mean(axis=0)[:2]
    act = ee_action(np.array([*xy, 0.06]), 0.0)
    for _ in range(3):
        env.step(act)
    state = u.get_state_dict()
    flat = u.get_state()
    first = []
    for _ in range(4):
        env.step(act)
        first.append(u.soft_nodes().copy())
    u.set_state_dict(state)
    second = []
    for _ in range(4):
        env.step(act)
        second.append(u.soft_nodes().copy())
    assert np.array_equal(np.stack(first), np.stack(second))
    u.set_state(flat)
    env.step(act)
    assert np.array_equal(u.soft_nodes(), first[0])


def test_ood_rescaling_changes_only_its_factor(env):
    env.reset(seed=5)
    nominal = env.unwrapped.evaluator_state()["object"]
    env.reset(seed=5, options={"youngs_modulus_scale": 0.5})
    soft = env.unwrapped.evaluator_state()["object"]
    assert soft["youngs_modulus"] == pytest.approx(0.5 * nominal["youngs_modulus"])
    assert soft["mass"] == pytest.approx(nominal["mass"], rel=1e-6)
    env.reset(seed=5, options={"mass_scale": 2.5})
    heavy = env.unwrapped.evaluator_state()["object"]
    assert heavy["mass"] == pytest.approx(2.5 * nominal["mass"], rel=1e-5)
    assert heavy["youngs_modulus"] == pytest.approx(nominal["youngs_modulus"])
    # Same seed, same placement: the rest poses differ only by the settling under the new load.
    assert np.linalg.norm(heavy["centroid"][:2] - nominal["centroid"][:2]) < 1e-3


def test_observations_carry_no_evaluator_state(env):
    obs, _ = env.reset(seed=2)
    nodes = env.unwrapped.soft_nodes()
    flat = np.asarray(obs).ravel()
    # Neither the centroid nor any node coordinate of the object appears in the state vector.
    for value in np.concatenate([nodes.mean(axis=0), nodes[:5].ravel()]):
        assert not np.any(np.isclose(flat, value, atol=1e-7, rtol=0))


def test_invalid_actions_raise_and_leave_the_state_untouched(env):
    env.reset(seed=4)
    u = env.unwrapped
    before = u.get_state().clone()
    for bad in (np.zeros(6, np.float32), np.full(7, np.nan, np.float32), np.array([0, 0, 0.1, np.pi, 0, 0, np.inf], np.float32)):
        with pytest.raises(ValueError, match="action"):
            env.step(bad)
    for bad in ("close the gripper", np.array([None] * 7, dtype=object)):
        with pytest.raises(ValueError, match="action must be numbers"):
            env.step(bad)
    assert u.elapsed_steps.item() == 0
    assert np.array_equal(u.get_state().numpy(), before.numpy())


def test_an_action_given_as_a_list_steps_like_the_same_array(env):
    action = ee_action(np.array([0.0, 0.0, 0.15]), 0.0)
    env.reset(seed=4)
    env.step(action)
    from_array = env.unwrapped.get_state().clone()
    env.reset(seed=4)
    env.step(action.tolist())
    assert np.array_equal(env.unwrapped.get_state().numpy(), from_array.numpy())


def test_closure_and_binary_gripper_encodings(env):
    from mani_skill_softvt.contracts.actions import closure_to_q, q_to_closure

    assert closure_to_q(0.0) == C.GRIPPER_Q_OPEN and closure_to_q(1.0) == C.GRIPPER_Q_CLOSED
    assert q_to_closure(closure_to_q(0.37)) == pytest.approx(0.37)
    binary = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose_binary")  # the module's env is pd_ee_pose
    for e in (env, binary):
        e.reset(seed=0)
        assert e.action_space.shape == (7,)
    for e, g, expected in ((env, 0.3, closure_to_q(0.3)), (binary, 0.7, C.GRIPPER_Q_CLOSED),
                           (binary, 0.2, C.GRIPPER_Q_OPEN)):
        e.unwrapped.agent.controller.controllers["gripper"].set_action(np.array([[g]], np.float32))
        target = e.unwrapped.agent.controller.controllers["gripper"]._target_qpos[0].numpy()
        assert target == pytest.approx([expected, expected], abs=1e-7)
    binary.close()
