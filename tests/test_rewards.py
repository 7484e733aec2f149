"""Dense and normalized-dense rewards: the staged maths without a simulator, then the env's glue on
a rigid suite (PhysX only) with a calibration card written for the test."""

import itertools

import gymnasium as gym
import numpy as np
import pytest
import torch

import mani_skill_softvt  # noqa: F401  (registers the envs)
from mani_skill_softvt.calibration.cards import write_card
from mani_skill_softvt.physics.config import physics_signature
from mani_skill_softvt.tasks import rewards as R
from mani_skill_softvt.contracts.actions import ee_action
from mani_skill_softvt.tasks.suites import task_spec

ENV_ID, SUITE, TASK = "SoftVTObjectRigid-v1", "object_rigid", 3
TAU_O = 0.04


# ---------------------------------------------------------------- pure functions
def test_distance_and_rest_rewards_fall_monotonically_from_one():
    for f, x in ((R.distance_reward, np.linspace(0.0, 1.0, 201)), (R.rest_reward, np.linspace(0.0, 2.0, 201))):
        r = f(x).numpy()
        assert r[0] == 1.0 and np.all((r >= 0) & (r <= 1))
        # Strictly falling while tanh is not yet saturated in float32, never rising after.
        assert np.all(np.diff(r[:60]) < 0) and np.all(np.diff(r) <= 0)
    # Half the reach reward at ~11 cm (k_d = 5 /m); an object at the 2 cm/s rest speed scores 0.8.
    assert float(R.distance_reward(np.arctanh(0.5) / R.DISTANCE_SCALE)) == pytest.approx(0.5, abs=1e-6)
    assert float(R.rest_reward(0.02)) == pytest.approx(1 - np.tanh(0.2), abs=1e-6)


def test_deformation_penalty_is_zero_within_the_tolerance_and_grows_beyond_bounded():
    within = R.deformation_penalty(np.linspace(0.0, 1.0, 11))
    assert torch.equal(within, torch.zeros(11))
    beyond = R.deformation_penalty(np.linspace(1.0, 5.0, 101)).numpy()
    assert np.all(np.diff(beyond) > 0) and beyond.max() < R.DEFORMATION_PENALTY_WEIGHT
    assert float(R.deformation_penalty(1e9)) <= R.DEFORMATION_PENALTY_WEIGHT
    assert float(R.deformation_penalty(2.0)) == pytest.approx(np.tanh(1.0), abs=1e-6)


def _staged(tcp=0.0, target=0.0, speed=0.0, grasped=False, in_target=False, success=False, ratio=0.0, collapsed=False):
    return float(R.staged_reward(tcp, target, speed, grasped, in_target, success, ratio, collapsed))


def test_staged_reward_is_bounded_and_success_is_the_maximum():
    rng = np.random.default_rng(0)
    n = 64
    for grasped, in_target, success in itertools.product([False, True], repeat=3):
        r = R.staged_reward(rng.uniform(0, 1, n), rng.uniform(0, 1, n), rng.uniform(0, 2, n), grasped, in_target,
                            success, rng.uniform(0, 10, n))
        assert r.shape == (n,) and r.dtype == torch.float32
        assert torch.all((r >= 0) & (r <= R.DENSE_REWARD_MAX))
        if success:
            assert torch.all(r == R.DENSE_REWARD_MAX)
        else:
            # Without success the four stages stay below the maximum, even at their best.
            assert torch.all(r < R.DENSE_REWARD_MAX)
            assert _staged(grasped=grasped, in_target=in_target) <= 4.0
    norm = R.normalized_reward(R.staged_reward([0.3, 0.0], 0.2, 0.0, [False, True], False, [False, True], 0.0))
    assert norm[0] == pytest.approx(float(R.distance_reward(0.3)) / 5) and norm[1] == 1.0


def test_stages_order_the_episode_and_letting_go_in_the_target_loses_nothing():
    far, near = _staged(tcp=0.4), _staged(tcp=0.01)
    grasped_far = _staged(tcp=0.01, target=0.3, grasped=True)
    grasped_near = _staged(tcp=0.01, target=0.02, grasped=True)
    held_in_target = _staged(tcp=0.01, target=0.02, grasped=True, in_target=True)
    released_moving = _staged(tcp=0.01, target=0.02, speed=0.2, in_target=True)
    released_at_rest = _staged(tcp=0.01, target=0.02, speed=0.0, in_target=True)
    assert far < near < grasped_far < grasped_near <= held_in_target < 5.0
    # Opening the hand over the target trades the grasp term for the rest term: at rest, no loss.
    assert released_moving < released_at_rest == pytest.approx(held_in_target)
    # Pushing the object towards the target without holding it earns no place reward.
    assert _staged(tcp=0.01, target=0.01) == _staged(tcp=0.01, target=0.5) == near


def test_deformation_within_the_tolerance_costs_nothing_and_beyond_it_lowers_the_reward():
    held = dict(tcp=0.01, target=0.1, grasped=True)
    assert _staged(**held, ratio=0.0) == _staged(**held, ratio=1.0)
    assert _staged(**held, ratio=1.0) > _staged(**held, ratio=1.5) > _staged(**held, ratio=3.0)
    assert _staged(**held, ratio=0.0) - _staged(**held, ratio=1e6) == pytest.approx(R.DEFORMATION_PENALTY_WEIGHT)
    # Never below zero, however far from the object and however squeezed.
    assert _staged(tcp=5.0, ratio=1e6) == 0.0
    # A collapsed tet costs the penalty's bound even within the tolerance; success still pays in full.
    assert _staged(**held, ratio=0.5, collapsed=True) == pytest.approx(_staged(**held, ratio=1e6))
    assert _staged(**held, success=True, collapsed=True) == R.DENSE_REWARD_MAX


# ---------------------------------------------------------------- the env
def _write_card(directory, asset_id):
    """A calibration card made for these tests, under the current physics (the env reads only tau_o)."""
    write_card({"asset_id": asset_id, "g_min": 0.4, "g_max": 0.8, "tau_o": TAU_O, "percentile": 95.0,
                "aperture_g_min_mm": 40.0, "aperture_g_max_mm": 30.0, "span_mm": 10.0, "records": [],
                "physics": physics_signature()}, directory)
    return directory


@pytest.fixture(scope="module")
def card_dir(tmp_path_factory):
    return _write_card(tmp_path_factory.mktemp("cards"), task_spec(SUITE, TASK).soft_asset_id)


@pytest.fixture(scope="module")
def dense_env(card_dir):
    env = gym.make(ENV_ID, task_id=TASK, obs_mode="none", reward_mode="dense", calibration_dir=str(card_dir))
    yield env
    env.close()


def _tcp(u):
    return u.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64)


def test_sparse_stays_the_default_reward_mode():
    env = gym.make(ENV_ID, task_id=TASK, obs_mode="none")
    assert env.unwrapped.reward_mode == "sparse"
    assert env.unwrapped.SUPPORTED_REWARD_MODES[0] == "sparse"
    env.close()


def test_dense_reward_rises_as_the_tcp_approaches_the_object(dense_env):
    env, u = dense_env, dense_env.unwrapped
    env.reset(seed=0)
    centroid = u.soft_nodes(u.target_instance).mean(axis=0)
    above = centroid + np.array([0.0, 0.0, 0.08])
    start = np.linalg.norm(centroid - _tcp(u))
    rewards, distances = [], []
    for _ in range(25):
        _, reward, *_ , info = env.step(ee_action(above, 0.0))
        assert reward.shape == (1,) and reward.dtype == torch.float32
        rewards.append(float(reward[0]))
        distances.append(np.linalg.norm(u.soft_nodes(u.target_instance).mean(axis=0) - _tcp(u)))
        assert not bool(info["is_grasped"][0])
    # Nothing grasped, nothing in the target: the reward is the reach term of the live distance.
    np.testing.assert_allclose(rewards, R.distance_reward(np.array(distances)).numpy(), atol=1e-5)
    assert distances[-1] < min(0.09, start - 0.05)
    # Every step that brought the TCP closer raised the reward; over the approach, by far.
    closer = np.diff(distances) < -1e-4
    assert closer.sum() >= 5 and np.all(np.diff(rewards)[closer] > 0)
    assert rewards[-1] > rewards[0] + 0.2


def test_deformation_beyond_tau_o_lowers_the_dense_reward(dense_env, monkeypatch):
    env, u = dense_env, dense_env.unwrapped
    env.reset(seed=0)
    above = u.soft_nodes(u.target_instance).mean(axis=0) + np.array([0.0, 0.0, 0.05])
    for _ in range(20):
        _, base, *_ = env.step(ee_action(above, 0.0))
    base = float(base[0])
    assert base > 0.7  # the reach term a few cm from the object
    assert u.deformation_tolerance == TAU_O  # the card's tau_o (a rigid twin reads its soft asset's card)
    # R_t = D_t / tau_o: within the tolerance nothing changes; at 1.5 the penalty is tanh(0.5); a
    # crushing squeeze costs the whole reach term but the reward does not go below zero.
    for ratio, expected in ((1.0, base), (1.5, base - np.tanh(0.5)), (1e3, 0.0)):
        monkeypatch.setattr(u, "deformation", lambda name=None, r=ratio: r * TAU_O)
        assert float(u.compute_dense_reward(None, None, u.get_info())[0]) == pytest.approx(expected, abs=1e-4)


def test_success_gives_the_maximum_and_normalized_dense_stays_in_unit_range(card_dir):
    env = gym.make(ENV_ID, task_id=TASK, obs_mode="none", reward_mode="normalized_dense",
                   calibration_dir=str(card_dir))
    u = env.unwrapped
    env.reset(seed=1)
    seen = []
    for _ in range(3):
        _, reward, _, _, info = env.step(ee_action(_tcp(u), 0.0))
        seen.append(float(reward[0]))
        assert reward == pytest.approx(float(u.compute_dense_reward(None, None, info)[0]) / R.DENSE_REWARD_MAX)
    # The instructed object at rest in the basket: success, the top of both scales.
    lo, hi = (np.asarray(v) for v in u.target_region)
    p = u.target.pose.p[0].cpu().numpy().astype(np.float64)
    u.place_object("object", np.array([p[0] + 0.5 * (lo[0] + hi[0]), p[1] + 0.5 * (lo[1] + hi[1]), p[2] + lo[2],
                                       1, 0, 0, 0]), settle_time=0.5)
    for _ in range(2):
        _, reward, _, _, info = env.step(ee_action(_tcp(u), 0.0))
        seen.append(float(reward[0]))
    assert bool(info["success"][0]) and seen[-1] == 1.0
    assert float(u.compute_dense_reward(None, None, info)[0]) == R.DENSE_REWARD_MAX
    assert all(0.0 <= r <= 1.0 for r in seen)
    env.close()


def test_a_missing_card_breaks_only_the_dense_reward_and_says_how_to_calibrate(tmp_path):
    soft_id = task_spec(SUITE, TASK).soft_asset_id
    sparse = gym.make(ENV_ID, task_id=TASK, obs_mode="none", calibration_dir=str(tmp_path))
    sparse.reset(seed=0)
    _, reward, *_ = sparse.step(ee_action(_tcp(sparse.unwrapped), 0.0))
    assert float(reward[0]) == 0.0
    sparse.close()
    dense = gym.make(ENV_ID, task_id=TASK, obs_mode="none", reward_mode="dense", calibration_dir=str(tmp_path))
    dense.reset(seed=0)  # the card is read by the first reward, not before
    with pytest.raises(FileNotFoundError) as e:
        dense.step(ee_action(_tcp(dense.unwrapped), 0.0))
    msg = str(e.value)
    assert soft_id in msg and f"python -m mani_skill_softvt.calibrate --assets {soft_id}" in msg
    assert task_spec(SUITE, TASK).asset_id in msg and "reward_mode='sparse'" in msg
    dense.close()


def test_dense_reward_of_a_soft_object_reads_its_fem_deformation(tmp_path):
    # One reset and two steps of the FEM suite (the expensive one): the same glue, D_t from the nodes.
    soft_id = task_spec("object_soft", TASK).soft_asset_id
    assert soft_id == task_spec(SUITE, TASK).soft_asset_id  # the twin and the soft object share one card
    env = gym.make("SoftVTObjectSoft-v1", task_id=TASK, obs_mode="none", reward_mode="dense",
                   calibration_dir=str(_write_card(tmp_path, soft_id)))
    u = env.unwrapped
    env.reset(seed=0)
    for _ in range(2):
        _, reward, *_ = env.step(ee_action(_tcp(u), 0.0))
    nodes = u.soft_nodes("object")
    ratio = u.deformation("object") / TAU_O
    assert 0.0 <= ratio < 1.0  # resting after the settle: within the tolerance, no penalty
    expected = R.distance_reward(np.linalg.norm(nodes.mean(axis=0) - _tcp(u)))
    assert float(reward[0]) == pytest.approx(float(expected), abs=1e-5)
    env.close()


def test_the_scorer_the_expert_and_the_dense_reward_read_one_card(card_dir, tmp_path):
    """make_env(calibration_dir=...) changes the card of all three at once: it is the env's."""
    from mani_skill_softvt.data.record import SoftVTRecordEpisode
    from mani_skill_softvt.evaluation.wrapper import make_env
    env = make_env(SUITE, TASK, obs_mode="none", reward_mode="dense", calibration_dir=card_dir)
    recorder = SoftVTRecordEpisode(env, output_dir=str(tmp_path), save_video=False, save_trajectory=False)
    card = env.unwrapped.calibration_card
    assert card.tau_o == TAU_O  # the test's card, not the package's
    assert env.calibration_card is card and recorder.unwrapped.calibration_card is card
    assert env.tau_o == env.unwrapped.deformation_tolerance == TAU_O
    recorder.close()
