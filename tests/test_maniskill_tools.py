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
from mani_skill_softvt.contracts.actions import GRIPPER_ACTION_VERSION
from mani_skill_softvt.tasks.suites import NUM_TASKS, SUITES, list_tasks

RIGID = "SoftVTObjectRigid-v1"
TASK = 3
RIGID_TASK = "SoftVTObjectRigid-Task3-v1"  # the task's own env id


def _leaves(group, prefix=""):
    for k, v in group.items():
        if isinstance(v, h5py.Group):
            yield from _leaves(v, f"{prefix}{k}/")
        else:
            yield f"{prefix}{k}", v


def _run(module: str, *args: str, ok: bool = True) -> subprocess.CompletedProcess | str:
    """A command as a user types it (a fresh process: nothing imported beforehand); its stdout, or
    with ``ok=False`` the finished process (a refusal: no traceback, the reason on stderr)."""
    proc = subprocess.run([sys.executable, "-m", module, *args], capture_output=True, text=True, timeout=600)
    if not ok:
        assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
        return proc
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout


@pytest.fixture(scope="module")
def mp_demo(tmp_path_factory) -> Path:
    """One rigid-suite expert trajectory from the package's motion-planning runner (pd_joint_pos)."""
    from mani_skill_softvt.expert.planner import MPLIB_PLANS, MPLIB_UNAVAILABLE
    from mani_skill_softvt.integrations.maniskill.motionplanning import main

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
    # The task's own id, module-qualified: gym.make of the id alone imports the package and makes task 3.
    assert meta["env_info"]["env_id"] == f"mani_skill_softvt:{RIGID_TASK}"
    assert mp_demo.parent.parent.name == RIGID_TASK  # <record-dir>/<env id>/motionplanning/, as ManiSkill's runner
    assert meta["env_info"]["env_kwargs"]["gripper_action_version"] == GRIPPER_ACTION_VERSION
    (ep,) = meta["episodes"]
    card = load_calibration_card(task_spec("object_rigid", TASK).soft_asset_id)
    assert ep["control_mode"] == "pd_joint_pos" and ep["success"]
    assert ep["instruction"] == list_tasks("object_rigid")[TASK].instruction
    assert card.g_min <= ep["closure"] <= card.g_max and ep["planner"] in ("mplib", "cartesian")
    with h5py.File(mp_demo, "r") as f:
        g = f["traj_0"]
        t = ep["elapsed_steps"]
        assert g["actions"].shape == (t, 8)  # 7 arm joint targets and the gripper
        # ManiSkill's normalised gripper: open (+1) at the start, the calibrated closure g as 1 - 2 g while
        # held; the binary twin closes (-1) on it.
        gripper = g["actions"][:, -1]
        assert gripper[0] == 1.0 and gripper.min() == pytest.approx(1 - 2 * ep["closure"], abs=1e-6)
        assert set(np.unique(g["actions_binary"][:, -1])) == {-1.0, 1.0}
        assert ((g["actions_binary"][:, -1] == -1.0) == (gripper < 1.0)).all()
        assert g["env_states/actors/object"].shape[0] == t + 1 and g["evaluator/nodes"].shape[0] == t + 1
        assert g["evaluator/deformation_ratio"].shape == (t + 1,) and g["evaluator/is_grasped"].shape == (t,)
        # The evaluator stream is beside the observations, never inside them.
        if "obs" in g:
            assert not any("evaluator" in k or "nodes" in k for k, _ in _leaves(g["obs"]))
        assert g.attrs["instruction"] == ep["instruction"] and int(g.attrs["seed"]) == ep["episode_seed"]


# Depth with touch by default; point clouds (a 400 MB file for one episode: 100,352 points a frame) and
# colour alone with -m slow (the same replay, other textures).
@pytest.mark.parametrize("obs_mode", [pytest.param("rgbd+tactile", marks=pytest.mark.slow),  # 46 s; the default run replays from the first state (below)
                                      pytest.param("pointcloud+tactile", marks=pytest.mark.slow),
                                      pytest.param("rgb+tactile", marks=pytest.mark.slow)])
def test_maniskill_replay_restores_the_recorded_states_and_renders_touch(mp_demo, tmp_path, obs_mode):
    # ManiSkill's module itself: the module-qualified env id makes gym import the package.
    src = _copy(mp_demo, tmp_path)
    out = _run("mani_skill.trajectory.replay_trajectory", "--traj-path", str(src), "--use-env-states",
               "-o", obs_mode, "--save-traj")
    assert "1/1" in out
    dst = tmp_path / f"{src.stem}.{obs_mode}.pd_joint_pos.physx_cpu.h5"
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
        if obs_mode.startswith("pointcloud"):  # both cameras' pixels as world points, with colour and ids
            n = 2 * 224 * 224
            assert obs["pointcloud/xyzw"].shape == (t + 1, n, 4) and obs["pointcloud/segmentation"].shape == (t + 1, n, 1)
            assert obs["pointcloud/rgb"].dtype == np.uint8 and "sensor_data/base_camera/rgb" not in obs
        else:
            assert obs["sensor_data/base_camera/rgb"].shape[0] == t + 1
        if obs_mode.startswith("rgbd"):
            assert obs["sensor_data/hand_camera/depth"].shape == (t + 1, 224, 224, 1)
            assert obs["sensor_data/hand_camera/depth"].dtype == np.int16


def test_replay_from_the_first_state_reproduces_the_episode(mp_demo, tmp_path):
    src = _copy(mp_demo, tmp_path)
    _run("mani_skill_softvt.integrations.maniskill.replay", "--traj-path", str(src), "--use-first-env-state", "-o", "state", "--save-traj")
    dst = tmp_path / f"{src.stem}.state.pd_joint_pos.physx_cpu.h5"
    with h5py.File(src, "r") as a, h5py.File(dst, "r") as b:
        # Restoring the first state and replaying the actions is deterministic: the same states.
        # (From state 1: ManiSkill 3.0.1 saves the recorded state 1 as state 0, see above.)
        np.testing.assert_array_equal(b["traj_0/env_states/actors/object"][1:], a["traj_0/env_states/actors/object"][1:])
        assert b["traj_0/success"][-1]


@pytest.mark.slow  # a rendered replay; ManiSkill's own replay of the same demo runs by default
def test_delta_mode_replay_loads_like_maniskills_diffusion_policy_data(mp_demo, tmp_path):
    src = _copy(mp_demo, tmp_path)
    _run("mani_skill_softvt.integrations.maniskill.replay", "--traj-path", str(src), "-c", "pd_ee_delta_pose", "-o", "rgb", "--save-traj")
    dst = tmp_path / f"{src.stem}.rgb.pd_ee_delta_pose.physx_cpu.h5"
    meta = json.loads(dst.with_suffix(".json").read_text())
    # The baseline's --env-id is the json's: the task's own id (ManiSkill's RecordEpisode would record the bare one).
    assert meta["env_info"]["env_id"] == f"mani_skill_softvt:{RIGID_TASK}"
    env = gym.make(meta["env_info"]["env_id"], obs_mode="rgb", control_mode="pd_ee_delta_pose")
    assert env.unwrapped.task.task_id == TASK
    # The baseline's agent asserts its action space is [-1, 1] throughout.
    assert (env.action_space.low == -1).all() and (env.action_space.high == 1).all()
    space = env.unwrapped.single_observation_space
    with h5py.File(dst, "r") as f:
        g = f["traj_0"]
        actions = g["actions"][()]
        t = len(actions)
        assert g["success"][-1]
        assert actions.shape == (t, 7) and np.abs(actions).max() <= 1.0  # normalised deltas and gripper
        with h5py.File(src, "r") as a:  # ManiSkill's converter carries the gripper over: the same encoding
            np.testing.assert_array_equal(np.unique(actions[:, -1]), np.unique(a["traj_0/actions"][:, -1]))

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
    _run("mani_skill_softvt.integrations.maniskill.replay", "--traj-path", str(src), "-c", mode, "--save-traj")
    with h5py.File(tmp_path / f"{src.stem}.none.{mode}.physx_cpu.h5", "r") as f:
        assert f["traj_0/success"][-1]
        gripper = f["traj_0/actions"][:, -1]
        if mode.endswith("_binary"):  # "close" is 1 in the paper's mode, ManiSkill's -1 in its own
            assert set(np.unique(gripper)) == ({0.0, 1.0} if mode == "pd_ee_pose_binary" else {-1.0, 1.0})
        elif mode == "pd_ee_pose":  # the closure again
            assert gripper.min() == 0.0 and 0.0 < gripper.max() <= 1.0


@pytest.mark.parametrize("env_id,obs_mode", [(RIGID, "state"), pytest.param(RIGID, "state_dict", marks=pytest.mark.slow),
                                             pytest.param(RIGID, "rgb", marks=pytest.mark.slow),
                                             pytest.param(RIGID, "rgb+tactile", marks=pytest.mark.slow),
                                             pytest.param("SoftVTObjectSoft-v1", "rgb+tactile", marks=pytest.mark.slow)])
def test_record_episode_records_flushes_and_saves_video(tmp_path, env_id, obs_mode):
    from mani_skill.utils.wrappers.record import RecordEpisode

    from mani_skill_softvt.contracts.actions import ee_action

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

    src = _copy(REPO_DIR / "demo-data" / "sample" / "object_soft" / f"task{TASK}.h5", tmp_path)
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
    from mani_skill_softvt.integrations.maniskill.motionplanning import main

    if not MPLIB_PLANS:
        pytest.skip(MPLIB_UNAVAILABLE)

    res = main(["-e", "SoftVTObjectSoft-v1", "--task-id", str(TASK), "-n", "1", "--record-dir", str(tmp_path)])
    src = Path(res["path"])
    assert json.loads(src.with_suffix(".json").read_text())["episodes"][0]["success"]
    _run("mani_skill_softvt.integrations.maniskill.replay", "--traj-path", str(src), "-c", "pd_ee_pose", "--save-traj")
    dst = src.with_name(f"{src.stem}.none.pd_ee_pose.physx_cpu.h5")
    with h5py.File(dst, "r") as f:
        assert f["traj_0/success"][-1] and f["traj_0/actions"].shape[1] == 7


# ---------------------------------------------------------------- env ids, bad input, old files
def test_every_task_has_its_own_env_id_beside_the_suites():
    from gymnasium.envs.registration import registry

    for suite in SUITES.values():
        assert registry[suite.env_id].kwargs["suite"] == suite.name  # the parametrised id, as before
        for k in range(NUM_TASKS):
            spec = registry[suite.task_env_id(k)]
            assert spec.kwargs["suite"] == suite.name and spec.kwargs["task_id"] == k
            assert spec.max_episode_steps == registry[suite.env_id].max_episode_steps
    assert SUITES["object_soft"].task_env_id(3) == "SoftVTObjectSoft-Task3-v1"
    # As ManiSkill's tools make it: the module-qualified id alone, no env kwargs.
    env = gym.make(f"mani_skill_softvt:{RIGID_TASK}", obs_mode="none")
    assert env.unwrapped.instruction == list_tasks("object_rigid")[TASK].instruction
    env.close()
    with pytest.raises(ValueError, match=r"SoftVTObjectRigid-Task3-v1 is task 3, but task_id=4.*SoftVTObjectRigid-Task4-v1"):
        gym.make(RIGID_TASK, task_id=4)


def _fake_trajectory(path: Path, env_id: str, control_mode: str = "pd_joint_pos", **kwargs) -> Path:
    """A small ManiSkill trajectory file pair (no physics): enough for the checks before a replay."""
    with h5py.File(path, "w") as f:
        f["traj_0/actions"] = np.zeros((3, 8), np.float32)
    meta = {"env_info": {"env_id": env_id, "env_kwargs": {"suite": "object_rigid", "task_id": TASK,
                                                          "control_mode": control_mode, **kwargs}},
            "episodes": [{"episode_id": 0, "control_mode": control_mode}]}
    path.with_suffix(".json").write_text(json.dumps(meta))
    return path


def test_replay_refuses_bad_input_naming_the_file_and_what_to_do(tmp_path):
    from mani_skill_softvt.integrations.maniskill.replay import main as replay_main

    current = {"gripper_action_version": GRIPPER_ACTION_VERSION}
    missing = tmp_path / "missing.h5"
    good = _fake_trajectory(tmp_path / "good.h5", f"mani_skill_softvt:{RIGID_TASK}", **current)
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(good.read_bytes()[:600])
    shutil.copy(good.with_suffix(".json"), truncated.with_suffix(".json"))
    no_json = tmp_path / "no_json.h5"
    shutil.copy(good, no_json)
    other = _fake_trajectory(tmp_path / "other.h5", "PickCube-v1", **current)
    cases = {missing: "does not exist", truncated: "truncated or corrupt", no_json: "no_json.json does not exist",
             other: "'PickCube-v1' is not a SoftVT env id"}
    for path, why in cases.items():
        with pytest.raises(SystemExit) as e:
            replay_main(["--traj-path", str(path), "-o", "state"])
        assert str(path.with_suffix(".json") if path is no_json else path) in e.value.code and why in e.value.code
    with pytest.raises(SystemExit, match="pd_ee_pose_euler: not a SoftVT control mode; choose one of"):
        replay_main(["--traj-path", str(good), "-c", "pd_ee_pose_euler"])
    # As a user runs it, where h5py used to end in its own traceback: the file named, what to do, no traceback.
    err = _run("mani_skill_softvt.integrations.maniskill.replay", "--traj-path", str(truncated), "-o", "state", ok=False).stderr
    assert err.startswith(f"python -m mani_skill_softvt.integrations.maniskill.replay: error: {truncated} is not a readable HDF5 file")
    assert "delete it and re-run the command that wrote it" in err


def test_an_old_joint_mode_file_is_refused_then_upgraded_in_place(mp_demo, tmp_path, capsys):
    from mani_skill_softvt.data.trajectory import gripper_action_problem, trajectory_json
    from mani_skill_softvt.integrations.maniskill.replay import check_input
    from mani_skill_softvt.integrations.maniskill.replay import main as replay_main

    # The same demo as written before the gripper was ManiSkill's: closures in [0, 1], no version, the suite's id.
    old = _copy(mp_demo, tmp_path)
    with h5py.File(old, "r+") as f:
        new_actions = f["traj_0/actions"][()]
        for key in ("actions", "actions_binary"):
            a = f[f"traj_0/{key}"][()]
            a[:, -1] = (a[:, -1] < 1.0) if key == "actions_binary" else 0.5 * (1.0 - a[:, -1])
            f[f"traj_0/{key}"][...] = a
    meta = json.loads(old.with_suffix(".json").read_text())
    meta["env_info"]["env_id"] = f"mani_skill_softvt:{RIGID}"
    del meta["env_info"]["env_kwargs"]["gripper_action_version"]
    old.with_suffix(".json").write_text(json.dumps(meta))

    with pytest.raises(SystemExit) as e:
        replay_main(["--traj-path", str(old), "-c", "pd_ee_delta_pose"])
    assert str(old) in e.value.code and f"--upgrade-gripper {old}" in e.value.code and "closures in [0, 1]" in e.value.code
    replay_main(["--upgrade-gripper", str(old)])
    assert "1 episodes converted" in capsys.readouterr().out
    with h5py.File(old, "r") as f, h5py.File(mp_demo, "r") as ref:
        np.testing.assert_allclose(f["traj_0/actions"][()], new_actions, atol=1e-6)
        np.testing.assert_array_equal(f["traj_0/actions_binary"][()], ref["traj_0/actions_binary"][()])
    meta = trajectory_json(old)
    assert meta["env_info"]["env_id"] == f"mani_skill_softvt:{RIGID_TASK}"
    assert gripper_action_problem(old, meta) is None and check_input(str(old), "pd_ee_delta_pose")
    replay_main(["--upgrade-gripper", str(old)])
    assert "already current" in capsys.readouterr().out


def test_motionplanning_refuses_bad_input_before_it_plans(tmp_path, capsys):
    from mani_skill_softvt.integrations.maniskill.motionplanning import main

    (tmp_path / RIGID_TASK / "motionplanning").mkdir(parents=True)
    (tmp_path / RIGID_TASK / "motionplanning" / "task3.h5").write_bytes(b"")
    cases = [
        (["-e", "SoftVTObjectSoftish-v1"], "'SoftVTObjectSoftish-v1' is not a SoftVT env id"),
        (["-e", RIGID_TASK, "--task-id", "4"], f"-e {RIGID_TASK} is task 3, but --task-id 4"),
        (["-e", RIGID, "--task-id", "12"], "task_id must be an integer in [0, 9]"),
        (["-e", RIGID_TASK, "--control-mode", "pd_ee_delta_pose"], "convert with `python -m mani_skill_softvt.integrations.maniskill.replay"),
        (["-e", f"mani_skill_softvt:{RIGID_TASK}", "--record-dir", str(tmp_path)], "task3.h5 exists"),
    ]
    for argv, why in cases:
        with pytest.raises(SystemExit) as e:
            main([*argv, "-n", "1"])
        assert e.value.code == 2
        assert why in capsys.readouterr().err


@pytest.mark.parametrize("obs_mode", [pytest.param("rgb", marks=pytest.mark.slow), "state"])  # 10-minute budget
def test_a_maniskill_checkpoint_sees_what_the_baselines_eval_env_shows_it(obs_mode):
    # ManiSkillDiffusionPolicy flattens the evaluator's observation as the baseline's evaluation env
    # does (FlattenRGBDObservationWrapper in rgb, the flat state in state).
    from mani_skill.utils.wrappers.flatten import FlattenRGBDObservationWrapper

    from mani_skill_softvt.integrations.maniskill.diffusion_policy import flatten_observation

    raw = gym.make(RIGID_TASK, obs_mode=obs_mode, control_mode="pd_ee_delta_pose")
    ours = flatten_observation(raw.reset(seed=0)[0])
    theirs = gym.make(RIGID_TASK, obs_mode=obs_mode, control_mode="pd_ee_delta_pose")
    if obs_mode == "rgb":
        theirs = FlattenRGBDObservationWrapper(theirs)
    expected = theirs.reset(seed=0)[0]
    expected = {k: v[0].numpy() for k, v in expected.items()} if obs_mode == "rgb" else {"state": expected[0].numpy()}
    assert ours.keys() == expected.keys()
    for k in ours:
        np.testing.assert_array_equal(ours[k], expected[k], err_msg=k)
    assert obs_mode != "rgb" or ours["rgb"].shape == (224, 224, 6)  # both cameras, side by side in channels
    raw.close()
    theirs.close()
