"""ManiSkill's own tools on SoftVT envs, as a ManiSkill user runs them: RecordEpisode, the
motion-planning runner, replay_trajectory (ManiSkill's module itself, and the package's entry
for conversions) and the data conventions of ManiSkill's diffusion-policy baseline."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import h5py
import numpy as np
import pytest

import mani_skill_softvt  # noqa: F401
from mani_skill_softvt.tasks.suites import list_tasks

RIGID = "SoftVTObjectRigid-v1"
TASK = 3


def _leaves(group, prefix=""):
    for k, v in group.items():
        if isinstance(v, h5py.Group):
            yield from _leaves(v, f"{prefix}{k}/")
        else:
            yield f"{prefix}{k}", v


def _run(module: str, *args: str) -> str:
    """A command as a user types it (a fresh process: nothing imported beforehand)."""
    proc = subprocess.run([sys.executable, "-m", module, *args], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout


@pytest.fixture(scope="module")
def mp_demo(tmp_path_factory) -> Path:
    """One rigid-suite expert trajectory from the package's motion-planning runner (pd_joint_pos)."""
    from mani_skill_softvt.expert.planner import MPLIB_PLANS, MPLIB_UNAVAILABLE
    from mani_skill_softvt.motionplanning import main

    if not MPLIB_PLANS:
        pytest.skip(MPLIB_UNAVAILABLE)

    out = tmp_path_factory.mktemp("mp")
    res = main(["-e", RIGID, "--task-id", str(TASK), "-n", "1", "--only-count-success", "--record-dir", str(out)])
    return Path(res["path"])


def _copy(src: Path, dst_dir: Path) -> Path:
    for suffix in (".h5", ".json"):
        shutil.copy(src.with_suffix(suffix), dst_dir / src.with_suffix(suffix).name)
    return dst_dir / src.name


def test_motionplanning_runner_records_maniskill_trajectories_with_the_evaluator_beside(mp_demo):
    from mani_skill_softvt.calibration.cards import load_calibration_card
    from mani_skill_softvt.tasks.suites import task_spec

    meta = json.loads(mp_demo.with_suffix(".json").read_text())
    assert meta["source_type"] == "motionplanning"
    assert meta["env_info"]["env_id"] == f"mani_skill_softvt:{RIGID}"  # gym.make imports the package by itself
    (ep,) = meta["episodes"]
    card = load_calibration_card(task_spec("object_rigid", TASK).soft_asset_id)
    assert ep["control_mode"] == "pd_joint_pos" and ep["success"]
    assert ep["instruction"] == list_tasks("object_rigid")[TASK].instruction
    assert card.g_min <= ep["closure"] <= card.g_max and ep["planner"] in ("mplib", "cartesian")
    with h5py.File(mp_demo, "r") as f:
        g = f["traj_0"]
        t = ep["elapsed_steps"]
        assert g["actions"].shape == (t, 8)  # 7 arm joint targets and the gripper closure
        assert g["env_states/actors/object"].shape[0] == t + 1 and g["evaluator/nodes"].shape[0] == t + 1
        assert g["evaluator/deformation_ratio"].shape == (t + 1,) and g["evaluator/is_grasped"].shape == (t,)
        # The evaluator stream is beside the observations, never inside them.
        if "obs" in g:
            assert not any("evaluator" in k or "nodes" in k for k, _ in _leaves(g["obs"]))
        assert g.attrs["instruction"] == ep["instruction"] and int(g.attrs["seed"]) == ep["episode_seed"]


def test_maniskill_replay_restores_the_recorded_states_and_renders_touch(mp_demo, tmp_path):
    # ManiSkill's module itself: the module-qualified env id makes gym import the package.
    src = _copy(mp_demo, tmp_path)
    out = _run("mani_skill.trajectory.replay_trajectory", "--traj-path", str(src), "--use-env-states",
               "-o", "rgb+tactile", "--save-traj")
    assert "1/1" in out
    dst = tmp_path / f"{src.stem}.rgb+tactile.pd_joint_pos.physx_cpu.h5"
    meta = json.loads(dst.with_suffix(".json").read_text())
    assert meta["episodes"][0]["success"]
    with h5py.File(src, "r") as a, h5py.File(dst, "r") as b:
        t = a["traj_0/actions"].shape[0]
        states = dict(_leaves(a["traj_0/env_states"]))
        for key, value in _leaves(b["traj_0/env_states"]):
            # Bit for bit after the reset. (ManiSkill 3.0.1's replay writes the recorded state 1 into
            # the saved state 0: it slices the list before its "replace the first saved state".)
            np.testing.assert_array_equal(value[1:], states[key][1:], err_msg=key)
        obs = b["traj_0/obs"]
        for side in ("left", "right"):
            assert obs[f"tactile/{side}/rgb"].shape == (t + 1, 240, 320, 3)
            assert obs[f"tactile/{side}/marker_current"].shape == (t + 1, 99, 2)
        assert obs["sensor_data/base_camera/rgb"].shape[0] == t + 1


def test_replay_from_the_first_state_reproduces_the_episode(mp_demo, tmp_path):
    src = _copy(mp_demo, tmp_path)
    _run("mani_skill_softvt.replay", "--traj-path", str(src), "--use-first-env-state", "-o", "state", "--save-traj")
    dst = tmp_path / f"{src.stem}.state.pd_joint_pos.physx_cpu.h5"
    with h5py.File(src, "r") as a, h5py.File(dst, "r") as b:
        # Restoring the first state and replaying the actions is deterministic: the same states.
        # (From state 1: ManiSkill 3.0.1 saves the recorded state 1 as state 0, see above.)
        np.testing.assert_array_equal(b["traj_0/env_states/actors/object"][1:], a["traj_0/env_states/actors/object"][1:])
        assert b["traj_0/success"][-1]


def test_delta_mode_replay_loads_like_maniskills_diffusion_policy_data(mp_demo, tmp_path):
    src = _copy(mp_demo, tmp_path)
    _run("mani_skill_softvt.replay", "--traj-path", str(src), "-c", "pd_ee_delta_pose", "-o", "rgb", "--save-traj")
    dst = tmp_path / f"{src.stem}.rgb.pd_ee_delta_pose.physx_cpu.h5"
    env = gym.make(RIGID, task_id=TASK, obs_mode="rgb", control_mode="pd_ee_delta_pose")
    space = env.unwrapped.single_observation_space
    with h5py.File(dst, "r") as f:
        g = f["traj_0"]
        actions = g["actions"][()]
        t = len(actions)
        assert g["success"][-1]
        assert actions.shape == (t, 7) and np.abs(actions[:, :6]).max() <= 1.0  # normalised deltas, the closure

        def check(node, sub):  # the baseline reorders the file's obs by the env's space: every key is there
            for k, s in sub.spaces.items():
                if isinstance(s, gym.spaces.Dict):
                    check(node[k], s)
                else:
                    assert node[k].shape == (t + 1, *s.shape), k  # T+1 observations for T actions
        check(g["obs"], space)
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["pd_ee_pose", "pd_ee_pose_binary", "pd_joint_pos_binary", "pd_joint_delta_pos"])
def test_replay_converts_into_every_control_mode(mp_demo, tmp_path, mode):
    src = _copy(mp_demo, tmp_path)
    _run("mani_skill_softvt.replay", "--traj-path", str(src), "-c", mode, "--save-traj")
    with h5py.File(tmp_path / f"{src.stem}.none.{mode}.physx_cpu.h5", "r") as f:
        assert f["traj_0/success"][-1]
        gripper = f["traj_0/actions"][:, -1]
        if mode.endswith("_binary"):
            assert set(np.unique(gripper)) == {0.0, 1.0}


@pytest.mark.parametrize("env_id,obs_mode", [(RIGID, "state"), pytest.param(RIGID, "state_dict", marks=pytest.mark.slow),
                                             pytest.param(RIGID, "rgb", marks=pytest.mark.slow),
                                             (RIGID, "rgb+tactile"), ("SoftVTObjectSoft-v1", "rgb+tactile")])
def test_record_episode_records_flushes_and_saves_video(tmp_path, env_id, obs_mode):
    from mani_skill.utils.wrappers.record import RecordEpisode

    from mani_skill_softvt.tasks.robot import ee_action

    env = RecordEpisode(gym.make(env_id, task_id=TASK, obs_mode=obs_mode, render_mode="rgb_array"), str(tmp_path),
                        trajectory_name="t",
                        save_video=True, source_type="test")
    env.reset(seed=0)
    tcp = env.unwrapped.agent.tcp.pose.p[0].numpy().astype(np.float64)
    for _ in range(3):
        env.step(ee_action(tcp, 0.0))
    env.flush_trajectory()
    env.flush_video()
    env.close()
    meta = json.loads((tmp_path / "t.json").read_text())
    assert meta["episodes"][0]["elapsed_steps"] == 3
    assert list(tmp_path.glob("*.mp4"))
    with h5py.File(tmp_path / "t.h5", "r") as f:
        assert f["traj_0/actions"].shape == (3, 7)
        if obs_mode == "rgb+tactile":
            assert f["traj_0/obs/tactile/left/rgb"].shape == (4, 240, 320, 3)


@pytest.fixture(scope="module")
def soft_demo(tmp_path_factory) -> Path:
    """The soft sample's episode (task 3, its first training seed) recorded again on this machine by
    the package's generator. Bit-for-bit replay holds on the machine that recorded: across machine
    instances the FEM rounds differently and contact amplifies it (docs/demos.md), so the committed
    sample is the reference only for what survives that (test below)."""
    out = tmp_path_factory.mktemp("soft")
    _run("mani_skill_softvt.demos", "generate", "--suite", "object_soft", "--tasks", str(TASK), "--num", "1",
         "--out", str(out))
    return out / "object_soft" / f"task{TASK}.h5"


@pytest.mark.slow
@pytest.mark.parametrize("flags,obs_mode", [((), "state"), (("--use-env-states",), "state"),
                                            (("--use-env-states",), "rgb+tactile")])
def test_maniskill_replay_of_a_soft_demo_reproduces_the_fem_state_bit_for_bit(soft_demo, tmp_path, flags, obs_mode):
    src = _copy(soft_demo, tmp_path)
    _run("mani_skill.trajectory.replay_trajectory", "--traj-path", str(src), *flags, "-o", obs_mode, "--save-traj")
    dst = tmp_path / f"{src.stem}.{obs_mode}.pd_ee_pose.physx_cpu.h5"
    with h5py.File(src, "r") as a, h5py.File(dst, "r") as b:
        assert b["traj_0/success"][-1]
        # Replaying the actions from the seed's reset is deterministic to the bit; with the recorded
        # states restored, from state 1 on (ManiSkill 3.0.1 saves state 1 as state 0, see above).
        start = 1 if flags else 0
        np.testing.assert_array_equal(b["traj_0/env_states/soft"][start:], a["traj_0/env_states/soft"][start:])
        if obs_mode == "rgb+tactile":
            t = a["traj_0/actions"].shape[0]
            assert b["traj_0/obs/tactile/left/depth"].shape == (t + 1, 240, 320)
            assert b["traj_0/obs/tactile/left/depth"][()].max() > 0  # the soft object pressed the gel


@pytest.mark.slow
def test_the_committed_soft_sample_replays_to_success_on_any_machine(soft_demo, tmp_path):
    from mani_skill_softvt.paths import REPO_DIR

    src = _copy(REPO_DIR / "demos" / "sample" / "object_soft" / f"task{TASK}.h5", tmp_path)
    _run("mani_skill.trajectory.replay_trajectory", "--traj-path", str(src), "-o", "state", "--save-traj")
    with h5py.File(src, "r") as a, h5py.File(tmp_path / f"{src.stem}.state.pd_ee_pose.physx_cpu.h5", "r") as b, \
            h5py.File(soft_demo, "r") as c:
        assert b["traj_0/success"][-1]
        # The same episode: the generator drew the same seed and the expert took as many steps.
        assert a["traj_0"].attrs["seed"] == c["traj_0"].attrs["seed"]
        assert a["traj_0/actions"].shape == c["traj_0/actions"].shape


@pytest.mark.slow
def test_soft_joint_space_demo_converts_into_the_papers_action_space(tmp_path):
    from mani_skill_softvt.expert.planner import MPLIB_PLANS, MPLIB_UNAVAILABLE
    from mani_skill_softvt.motionplanning import main

    if not MPLIB_PLANS:
        pytest.skip(MPLIB_UNAVAILABLE)

    res = main(["-e", "SoftVTObjectSoft-v1", "--task-id", str(TASK), "-n", "1", "--record-dir", str(tmp_path)])
    src = Path(res["path"])
    assert json.loads(src.with_suffix(".json").read_text())["episodes"][0]["success"]
    _run("mani_skill_softvt.replay", "--traj-path", str(src), "-c", "pd_ee_pose", "--save-traj")
    dst = src.with_name(f"{src.stem}.none.pd_ee_pose.physx_cpu.h5")
    with h5py.File(dst, "r") as f:
        assert f["traj_0/success"][-1] and f["traj_0/actions"].shape[1] == 7
