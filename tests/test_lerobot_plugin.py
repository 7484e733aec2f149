"""The lerobot_env_softvt plugin, with LeRobot's own code and commands (the LeRobot stack only:
``bash scripts/setup.sh lerobot``; skipped where LeRobot is not installed).

The loop a LeRobot user runs, end to end (slow): render and export demos, ``lerobot-train`` a
small Diffusion Policy on the export (CPU), ``lerobot-eval`` it through the plugin, and read the
SoftVT records and report it leaves in its output directory.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

lerobot = pytest.importorskip("lerobot", reason="the LeRobot stack (bash scripts/setup.sh lerobot) has LeRobot")

from lerobot.envs.configs import EnvConfig  # noqa: E402
from lerobot.envs.factory import make_env_config  # noqa: E402
from lerobot.envs.utils import env_to_policy_features  # noqa: E402
from lerobot.utils.import_utils import register_third_party_plugins  # noqa: E402

from mani_skill_softvt.integrations.lerobot.export import frame_feature_shapes  # noqa: E402
from mani_skill_softvt.evaluation.records import read_records  # noqa: E402
from mani_skill_softvt.paths import REPO_DIR  # noqa: E402

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")
BIN = Path(sys.executable).parent
ALLOWED = ("observation.images.", "observation.state", "observation.tactile.", "observation.depth.")  # the export's names


@pytest.fixture(scope="module", autouse=True)
def plugin():
    register_third_party_plugins()  # what lerobot-eval does first: imports lerobot_env_softvt
    return EnvConfig.get_choice_class("softvt")


def test_the_plugin_declares_the_exports_features():
    cfg = make_env_config("softvt", task="SoftVTObjectSoft-v1", task_ids=[3], camera_size="84x84", image_size="64x64")
    features = env_to_policy_features(cfg)
    shapes = frame_feature_shapes("rgb+tactile", (84, 84), (64, 64))
    expected = {k: (s[2], s[0], s[1]) if k.startswith("observation.images.") else s for k, s in shapes.items()}
    assert {k: tuple(f.shape) for k, f in features.items() if k != "action"} == expected
    assert tuple(features["action"].shape) == (7,)


def test_an_rgbd_export_loads_in_lerobot_with_depth_in_metres_and_the_plugin_declares_it(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    sys.path.insert(0, str(REPO_DIR / "tests"))
    from test_lerobot_export import _fake_pair  # a small synthetic rendering, camera depth included

    from mani_skill_softvt.integrations.lerobot.export import depth_sources, export_lerobot

    src = _fake_pair(tmp_path / "src", t=6, depth=True)
    export_lerobot([src], tmp_path / "ds", use_videos=False)
    ds = LeRobotDataset("local/softvt-depth", root=tmp_path / "ds")
    import h5py

    with h5py.File(src.rendered_h5, "r") as f:
        for feat, key in depth_sources().items():
            got = ds[2][feat].numpy()
            assert got.shape == (16, 16, 1)
            np.testing.assert_array_equal(got, f[f"traj_0/obs/{key}"][2].astype(np.float32) / 1000)
            assert ds.meta.stats[feat]["mean"].shape == (16, 16, 1)
    cfg = make_env_config("softvt", task="SoftVTObjectRigid-v1", task_ids=[3], obs_type="rgbd+tactile",
                          camera_size="84x84", image_size="64x64")
    features = env_to_policy_features(cfg)
    assert tuple(features["observation.depth.base_camera"].shape) == (64, 64, 1)


@pytest.mark.parametrize("kwargs, message", [
    ({"task": "PickCube-v1"}, "unknown SoftVT env id"),
    ({"protocol": "odd"}, "--env.protocol=odd"),
    ({"protocol": "ood", "conditions": ["mass_x9"]}, "unknown \\['mass_x9'\\]"),
    ({"task_ids": [10]}, "out of range"),
    ({"camera_size": "84"}, "--env.camera_size '84'"),
])
def test_bad_values_are_refused_by_name(kwargs, message):
    with pytest.raises(ValueError, match=message):
        make_env_config("softvt", **kwargs)


def test_a_lerobot_policy_sees_observations_only_and_a_nan_is_a_recorded_result(tmp_path):
    # LeRobot's own rollout loop, with a stand-in policy that notes what it is given and answers
    # NaN on its third call: it is handed the export's features (and the instruction) only, and
    # the NaN ends the episode as policy_error, recorded, the run going on.
    import torch
    from lerobot.scripts.lerobot_eval import rollout

    class Spy(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.seen, self.calls = set(), 0

        def reset(self):
            pass

        def select_action(self, batch):
            self.seen |= set(batch)
            self.calls += 1
            return torch.full((1, 7), float("nan") if self.calls == 3 else 0.0)

    cfg = make_env_config("softvt", task="SoftVTObjectSoft-v1", task_ids=[3], protocol="ood",
                          conditions=["youngs_modulus_x0.5"], camera_size="84x84", image_size="64x64",
                          records_dir=str(tmp_path))
    envs = cfg.create_envs(n_envs=1)
    assert list(envs) == ["object_soft/youngs_modulus_x0.5"]
    env = envs["object_soft/youngs_modulus_x0.5"][3]
    spy, identity = Spy(), (lambda x: x)  # no normalisation: the spy reads what the env gives
    out = rollout(env, spy, identity, identity, identity, identity, seeds=[0])
    env.close()
    assert spy.seen - {"task"} and all(k.startswith(ALLOWED) for k in spy.seen - {"task"}), spy.seen
    assert not out["success"].any() and spy.calls == 3
    (rec,) = read_records(next(tmp_path.glob("*.jsonl")))  # --env.records_dir: the records go there
    assert rec["termination"] == "policy_error" and rec["steps"] == 2 and rec["condition"] == "youngs_modulus_x0.5"
    assert rec["receipt"]["stack"]["numpy"] == np.__version__ and rec["receipt"]["stack"]["python"].startswith("3.12")


@pytest.mark.slow
def test_the_lerobot_users_loop_trains_evaluates_and_leaves_softvt_records(tmp_path):
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "WANDB_MODE": "disabled"}

    def run(*cmd):
        done = subprocess.run([str(c) for c in cmd], cwd=tmp_path, env=env, capture_output=True, text=True)
        assert done.returncode == 0, f"{cmd[0]} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        return done

    demos = tmp_path / "demos"
    shutil.copytree(REPO_DIR / "demo-data" / "sample", demos)
    py = sys.executable
    run(py, "-m", "mani_skill_softvt.demos", "render", "--suite", "object_soft", "--tasks", "3", "--out", demos,
        "--camera-size", "84x84")
    run(py, "-m", "mani_skill_softvt.demos", "export-lerobot", "--suite", "object_soft", "--tasks", "3", "--out", demos,
        "--camera-size", "84x84", "--image-size", "64x64", "--lerobot-out", tmp_path / "dataset")
    # A small Diffusion Policy on the CPU: no pretrained backbone (it would be downloaded).
    run(BIN / "lerobot-train", "--dataset.repo_id=local/softvt", f"--dataset.root={tmp_path / 'dataset'}",
        "--dataset.video_backend=pyav", "--policy.type=diffusion", "--policy.device=cpu", "--policy.push_to_hub=false",
        "--policy.pretrained_backbone_weights=null", "--policy.down_dims=[64,128,256]", "--policy.crop_shape=[56,56]",
        "--steps=200", "--batch_size=4", "--num_workers=0", "--save_freq=200", "--log_freq=50",
        f"--output_dir={tmp_path / 'train'}", "--wandb.enable=false")
    policy = tmp_path / "train" / "checkpoints" / "last" / "pretrained_model"
    run(BIN / "lerobot-eval", f"--policy.path={policy}", "--policy.device=cpu", "--env.type=softvt",
        "--env.task=SoftVTObjectSoft-v1", "--env.task_ids=[3]", "--env.camera_size=84x84", "--env.image_size=64x64",
        "--eval.n_episodes=1", "--eval.batch_size=1", "--seed=0", f"--output_dir={tmp_path / 'eval'}")
    info = json.loads((tmp_path / "eval" / "eval_info.json").read_text())
    (records_file,) = (tmp_path / "eval" / "softvt").glob("*.jsonl")
    (rec,) = read_records(records_file)
    # lerobot-eval's success rate is our TSR; our record adds how hard the policy squeezed.
    assert info["overall"]["pc_success"] == 100.0 * rec["success"]
    assert rec["policy"] == f"lerobot:diffusion@{policy}" and len(rec["policy_sha256"]) == 64
    assert rec["termination"] in ("success", "dropped", "timeout", "sim_unstable") and rec["r_max"] >= 0.0
    assert rec["obs_mode"] == "rgb+tactile" and rec["camera_size"] == [84, 84] and rec["seed"] == 50003000
    assert records_file.with_suffix(".md").exists() and records_file.with_name(records_file.stem + "_traces.png").exists()
    # Our tools read them: a rescore at another percentile, with no new rollouts.
    rescored = run(py, "-m", "mani_skill_softvt.evaluate", "--rescore", records_file, "--percentile", "80",
                   "--out", tmp_path / "rescored")
    assert "## Overall" in rescored.stdout
    # A second run into the same output directory is refused, nothing overwritten.
    again = subprocess.run([str(BIN / "lerobot-eval"), f"--policy.path={policy}", "--policy.device=cpu",
                            "--env.type=softvt", "--env.task_ids=[3]", "--env.camera_size=84x84",
                            "--env.image_size=64x64", "--eval.n_episodes=1", "--eval.batch_size=1", "--seed=0",
                            f"--output_dir={tmp_path / 'eval'}"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert again.returncode != 0 and "already holds SoftVT records" in again.stdout + again.stderr
    assert len(read_records(records_file)) == 1
