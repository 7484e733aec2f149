"""LeRobotEnv: a SoftVT task as lerobot-eval steps it (no LeRobot needed here; the plugin's own
tests, tests/test_lerobot_plugin.py, run on the LeRobot stack)."""

import numpy as np
import pytest

from mani_skill_softvt.integrations.lerobot.export import frame_feature_shapes
from mani_skill_softvt.data.seeds import id_seed
from mani_skill_softvt.integrations.lerobot.env import LeRobotEnv, lerobot_observation, suite_of_env_id
from mani_skill_softvt.evaluation.records import read_records, record_hash
from mani_skill_softvt.paths import REPO_DIR
from mani_skill_softvt.tasks.suites import OOD_CONDITIONS, task_spec

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

# What a LeRobot policy may see: the export's features, as LeRobot's env keys.
POLICY_KEYS = {"pixels", "agent_pos", "tactile.left.marker_initial", "tactile.left.marker_current",
               "tactile.right.marker_initial", "tactile.right.marker_current"}


def test_env_ids_name_suites_and_keys_map_back_to_the_export():
    assert suite_of_env_id("SoftVTObjectSoft-v1") == "object_soft"
    assert suite_of_env_id("SoftVTSpatialRigid-v1") == "spatial_rigid"
    with pytest.raises(ValueError, match="unknown SoftVT env id 'PickCube-v1'"):
        suite_of_env_id("PickCube-v1")
    shapes = frame_feature_shapes("rgb+tactile", (84, 84), (64, 64))
    obs = lerobot_observation({k: np.zeros(s) for k, s in shapes.items()})
    assert set(obs) == POLICY_KEYS
    assert set(obs["pixels"]) == {"base_camera", "hand_camera", "tactile_left", "tactile_right"}
    # LeRobot's preprocess_observation puts the prefixes back: pixels/k -> observation.images.k,
    # agent_pos -> observation.state, k -> observation.k; that gives the export's names.
    names = {f"observation.images.{k}" for k in obs["pixels"]} | {"observation.state"}
    names |= {f"observation.{k}" for k in obs if k not in ("pixels", "agent_pos")}
    assert names == set(shapes)


def test_seeds_name_protocol_episodes_and_a_bad_action_is_a_recorded_result(tmp_path):
    records = tmp_path / "softvt" / "records.jsonl"
    # As lerobot-eval runs it with its default seed (1000) and --eval.n_episodes=3.
    env = LeRobotEnv("object_soft", 3, protocol="ood", condition="mass_x2.5", camera_size=(84, 84),
                     image_size=(64, 64), records=records, policy_spec="lerobot:test", first_seed=1000,
                     recorded_episodes=3)
    assert env.task_description == task_spec("object_soft", 3).instruction
    assert env._max_episode_steps == 300
    with pytest.raises(ValueError, match="seed -1: .* seed >= 0"):
        env.reset(seed=-1)
    # Seed 1003 is LeRobot's batch padding past the 3 episodes it counts: it ends at once, unrecorded.
    obs, info = env.reset(seed=1003)
    assert env.step(np.zeros(7, np.float32))[2] and not records.exists()
    obs, info = env.reset(seed=1002)  # the protocol's episode 1002 mod 50 = 2
    # The observation is the policy's streams only, each as its space says.
    assert set(obs) == POLICY_KEYS and env.observation_space.contains(obs), {k: np.shape(v) for k, v in obs.items()}
    assert obs["pixels"]["base_camera"].shape == (64, 64, 3) and obs["pixels"]["tactile_left"].dtype == np.uint8
    assert info["is_success"] is False and info["r_max"] >= 0.0 and info["termination"] == ""
    # A NaN action ends the episode as policy_error, with its record; the env changes nothing after.
    obs2, reward, terminated, truncated, info = env.step(np.full(7, np.nan, np.float32))
    assert terminated and not truncated and info["termination"] == "policy_error" and not info["is_success"]
    assert env.step(np.zeros(7, np.float32))[2]
    frame = env.render()  # the human-view camera's frame, as LeRobot's videos take it
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    env.close()
    (rec,) = read_records(records)
    assert rec["termination"] == "policy_error" and "NaN" in rec["error"] and rec["steps"] == 0
    assert (rec["task_id"], rec["condition"], rec["seed"]) == (3, "mass_x2.5", id_seed(3, 2))
    assert rec["receipt"]["mass"] == pytest.approx(2.5 * _nominal_mass(3), rel=1e-6)
    assert rec["record_sha256"] == record_hash({k: v for k, v in rec.items() if k != "wall_s"})
    assert rec["camera_size"] == [84, 84] and rec["policy"] == "lerobot:test" and not rec["receipt"]["privileged"]
    assert (records.parent / "records.md").exists()  # the report, written when the env closes
    assert OOD_CONDITIONS["mass_x2.5"] == ("mass_scale", 2.5)


def _nominal_mass(task_id: int) -> float:
    """The object's mass in a committed ID record of the task (nominal factors)."""
    committed = read_records(REPO_DIR / "campaign-data" / "results" / "object_soft_id_vo-c-cpu.jsonl")
    return next(r["receipt"]["mass"] for r in committed if r["task_id"] == task_id)


@pytest.mark.slow
def test_an_episode_through_lerobots_loop_scores_as_the_evaluators(tmp_path):
    # The same actions through LeRobotEnv (one a step, as lerobot-eval drives it) and through the
    # evaluator's rollout give the same record, bit for bit, but for who ran it and the wall time.
    from mani_skill_softvt.evaluation.policies import RandomPolicy
    from mani_skill_softvt.evaluation.protocols import episodes
    from mani_skill_softvt.evaluation.runner import run_episode
    from mani_skill_softvt.evaluation.wrapper import make_env

    actions = []

    class Logged(RandomPolicy):
        def act(self, obs):
            a = super().act(obs)
            actions.append(a[0].copy())
            return a

    episode = episodes("object_soft", "id", [3], 1)[0]
    env = make_env("object_soft", 3, obs_mode="state_dict")
    ours = run_episode(env, Logged(), episode)
    env.close()
    records = tmp_path / "r.jsonl"
    lr = LeRobotEnv("object_soft", 3, obs_mode="state_dict", records=records, policy_spec=ours["policy"])
    lr.reset(seed=0)
    for a in actions:
        _, _, terminated, truncated, _ = lr.step(a)
        if terminated or truncated:
            break
    lr.close()
    (theirs,) = read_records(records)

    def strip(r):
        return {**{k: v for k, v in r.items() if k not in ("wall_s", "record_sha256")},
                "receipt": {k: v for k, v in r["receipt"].items() if k != "policy"}}

    assert strip(theirs) == strip(ours)
    assert ours["steps"] == len(actions) and max(ours["deformation_trace"]) > 0.0


def test_rgbd_observations_carry_each_cameras_depth_in_metres_as_the_export_does():
    """An rgbd+tactile env gives LeRobot ``depth.<camera>`` beside the images (observation.depth.<camera>
    once LeRobot adds its prefix: the export's name), float32 metres, nearest-neighbour resized."""
    shapes = frame_feature_shapes("rgbd+tactile", (84, 84), (64, 64))
    assert shapes["observation.depth.base_camera"] == (64, 64, 1)
    env = LeRobotEnv("object_rigid", 3, obs_mode="rgbd+tactile", camera_size=(84, 84), image_size=(64, 64))
    obs, _ = env.reset(seed=0)
    assert set(obs) == POLICY_KEYS | {"depth.base_camera", "depth.hand_camera"}
    assert env.observation_space.contains(obs)
    depth = obs["depth.base_camera"]
    assert depth.dtype == np.float32 and np.allclose(depth * 1000, np.round(depth * 1000), atol=1e-3)  # whole mm
    # The third-person camera looks down on the table from about half a metre: depths of that order.
    seen = depth[depth > 0]
    assert seen.size > 0.5 * depth.size and 0.2 < np.median(seen) < 1.5, (seen.size / depth.size, np.median(seen))
    env.close()
