"""ManiSkill's ``replay_trajectory`` on SoftVT trajectories: ``python -m mani_skill_softvt.integrations.maniskill.replay``.

Every flag is ManiSkill's own, handed over unchanged (``--traj-path``, ``-o``, ``-c``,
``--use-env-states``, ``--use-first-env-state``, ``--save-traj``, ``--save-video``, ``-n`` ...;
``--help`` lists them)::

    python -m mani_skill_softvt.integrations.maniskill.replay --traj-path demo-data/sample/object_soft/task3.h5 \\
        --use-env-states -o rgb+tactile --save-traj
    python -m mani_skill_softvt.integrations.maniskill.replay --traj-path FILE.h5 --use-env-states -o pointcloud+tactile --save-traj
    python -m mani_skill_softvt.integrations.maniskill.replay --traj-path FILE.h5 -c pd_ee_delta_pose -o rgb --save-traj

Output goes beside the input as ``<name>.<obs_mode>.<control_mode>.physx_cpu.h5`` + ``.json``
(ManiSkill's naming), its json naming the task's own env id, module-qualified
(``mani_skill_softvt:SoftVTObjectSoft-Task3-v1``): ManiSkill's baselines take that id as their
``--env-id``. Files recorded by this package name their env that way, so
``python -m mani_skill.trajectory.replay_trajectory`` itself replays them too (its output json
records the bare id). This entry adds what ManiSkill's converter cannot know (``-c`` from
``pd_joint_pos``, the mode motion-planning demos are recorded in):

- into ``pd_ee_pose`` / ``pd_ee_pose_binary``: SoftVT's absolute pose is an axis-angle, while
  ManiSkill's converter writes XYZ Euler angles. Each step's target is the TCP pose of the
  recorded joint target (forward kinematics), as ManiSkill's converter aims at the target and
  not at the lagging arm; the gripper becomes the paper's closure g = (1 - a) / 2;
- into any ``*_binary`` mode (``pd_joint_pos_binary`` included, which ManiSkill does not convert
  to): any commanded closure > 0 becomes "close" (-1 in ManiSkill's modes, 1 in ``pd_ee_pose_binary``);
  ManiSkill would copy the value, and a calibrated closure would read as half open.

Into ``pd_joint_delta_pos`` and ``pd_ee_delta_pose`` it is ManiSkill's converter: their gripper
action is ManiSkill's normalised one, as ``pd_joint_pos``'s (:mod:`mani_skill_softvt.tasks.robot`).

Bad input is refused before anything runs, naming the file and what to do: a missing or
truncated h5, a missing json, an env id that is not SoftVT's, a joint- or delta-mode file whose
gripper actions are closures in [0, 1] (written before version 2 of the gripper encoding:
``python -m mani_skill_softvt.integrations.maniskill.replay --upgrade-gripper FILE.h5`` converts it in place).
"""

from __future__ import annotations

import multiprocessing as mp
import sys
import types
from pathlib import Path

import numpy as np
from mani_skill.trajectory import replay_trajectory

from ... import tasks  # noqa: F401  (registers the SoftVT envs before ManiSkill makes one)
from ...data.trajectory import (
    check_h5,
    gripper_action_problem,
    trajectory_control_mode,
    trajectory_json,
    upgrade_gripper_actions,
)
from ...fileio import atomic_write_json, read_json
from ...contracts.observations import ObsMode
from ...physics.transforms import quat_to_rotvec
from ...contracts.actions import CONTROL_MODES, UPGRADE_COMMAND, action_closure, gripper_action, normalized_gripper
from ...tasks.suites import parse_env_id, recorded_env_id

PROG = "python -m mani_skill_softvt.integrations.maniskill.replay"


class _BinaryGripperEnv:
    """The env a converter steps, with every action's gripper made the binary command of ``mode``
    on the way in: "close" for any commanded closure > 0 (the arm mode's gripper encoding in, see
    :func:`~mani_skill_softvt.contracts.actions.gripper_action`)."""

    def __init__(self, env, mode: str):
        self._env = env
        self._mode = mode

    def step(self, action):
        a = np.array(action.cpu() if hasattr(action, "cpu") else action, dtype=np.float32, copy=True)
        closure = action_closure(a[..., -1], self._mode.removesuffix("_binary"))
        a[..., -1] = gripper_action(closure, self._mode)
        return self._env.step(a)

    def __getattr__(self, name):
        return getattr(self._env, name)


def joint_pos_to_ee_pose(output_mode, ori_actions, ori_env, env, render=False, pbar=None, verbose=False) -> dict:
    """Replay ``pd_joint_pos`` actions in ``env`` (``pd_ee_pose``, axis-angle): per step the TCP
    pose (robot base frame) that the recorded arm joint target reaches, and the recorded gripper.
    The signature is ManiSkill's converters'; ``ori_env`` is not stepped (the target is the action)."""
    u = env.unwrapped
    arm = u.agent.controller.controllers["arm"]
    pin = u.agent.robot.create_pinocchio_model()
    tcp_index = arm.ee_link.index
    joints = arm.active_joint_indices.cpu().numpy()
    info, rotvec = {}, None
    if pbar is not None:
        pbar.reset(total=len(ori_actions))
    for a in np.asarray(ori_actions, np.float64):
        q = u.agent.robot.get_qpos()[0].cpu().numpy().astype(np.float64)
        q[joints] = a[: len(joints)]
        pin.compute_forward_kinematics(q)
        pose = pin.get_link_pose(tcp_index)  # root (= base) frame, [p, q_wxyz]
        p, quat = np.asarray(pose.p, np.float64), np.asarray(pose.q, np.float64)
        rotvec = quat_to_rotvec(quat, reference=rotvec)  # the branch next to the last: a continuous stream
        closure = action_closure(a[-1], "pd_joint_pos")  # ManiSkill's normalised gripper -> pd_ee_pose's closure
        _, _, _, _, info = env.step(np.concatenate([p, rotvec, [closure]]).astype(np.float32))
        if pbar is not None:
            pbar.update()
        if render:
            u.render_human()
    return info


def replay_actions(actions, env, render=False, pbar=None) -> dict:
    """Step ``env`` through ``actions`` as they are (a mode whose arm action is the recorded one)."""
    info = {}
    if pbar is not None:
        pbar.reset(total=len(actions))
    for a in np.asarray(actions, np.float32):
        _, _, _, _, info = env.step(a)
        if pbar is not None:
            pbar.update()
        if render:
            env.unwrapped.render_human()
    return info


def _patch_conversion(replay_trajectory) -> None:
    """Route ``-c`` conversions from ``pd_joint_pos`` that need SoftVT's conventions (module docstring)."""
    original = replay_trajectory.action_conversion.from_pd_joint_pos

    def from_pd_joint_pos(output_mode, ori_actions, ori_env, env, render=False, pbar=None, verbose=False):
        if output_mode.endswith("_binary"):
            env = _BinaryGripperEnv(env, output_mode)
        arm_mode = output_mode.removesuffix("_binary")
        if arm_mode == "pd_joint_pos":  # only the gripper's encoding changes
            return replay_actions(ori_actions, env, render, pbar)
        if arm_mode == "pd_ee_pose":
            return joint_pos_to_ee_pose(arm_mode, ori_actions, ori_env, env, render, pbar, verbose)
        return original(arm_mode, ori_actions, ori_env, env, render=render, pbar=pbar, verbose=verbose)

    # replay_trajectory calls action_conversion.from_pd_joint_pos through its own module attribute:
    # give it a namespace with ManiSkill's converters and this dispatcher (ManiSkill's module is untouched).
    namespace = types.SimpleNamespace(**{k: v for k, v in vars(replay_trajectory.action_conversion).items()
                                         if not k.startswith("__")})
    namespace.from_pd_joint_pos = from_pd_joint_pos
    replay_trajectory.action_conversion = namespace


def _refuse(message: str) -> None:
    """Exit as an argument error does: the problem (naming the file) and what to do, no traceback."""
    raise SystemExit(f"{PROG}: error: {message}")


def check_input(traj_path: str, target_control_mode: str | None) -> dict:
    """The trajectory's json, after checking what replaying ``traj_path`` needs: a readable h5 (the
    same check as ``demos``), its json, a SoftVT env id, gripper actions in this version's encoding,
    and a conversion this entry can make. Refuses (SystemExit) naming the file and what to do."""
    problem = check_h5(Path(traj_path), read=False)
    if problem:
        _refuse(problem)
    try:
        meta = trajectory_json(Path(traj_path))
        parse_env_id(meta["env_info"]["env_id"])
    except (FileNotFoundError, ValueError) as e:  # the json's errors name the json; the env id's, no file
        _refuse(str(e) if str(Path(traj_path).with_suffix("")) in str(e) else f"{traj_path}: {e}")
    problem = gripper_action_problem(Path(traj_path), meta)
    if problem:
        _refuse(problem)
    source = trajectory_control_mode(meta)
    if target_control_mode is not None and target_control_mode != source:
        if target_control_mode not in CONTROL_MODES:
            _refuse(f"-c {target_control_mode}: not a SoftVT control mode; choose one of {CONTROL_MODES}")
        # ManiSkill converts from pd_joint_delta_pos too, carrying the gripper over: right only between
        # its own continuous-gripper modes. Everything else goes through pd_joint_pos (_patch_conversion).
        maniskill_only = (source == "pd_joint_delta_pos" and normalized_gripper(target_control_mode)
                          and not target_control_mode.endswith("_binary"))
        if source != "pd_joint_pos" and not maniskill_only:
            _refuse(f"{traj_path} holds {source} actions; -c converts from pd_joint_pos (what "
                    f"`python -m mani_skill_softvt.integrations.maniskill.motionplanning` records by default): record in pd_joint_pos, then "
                    f"convert with -c {target_control_mode}")
    return meta


def record_task_env_id(traj_path: str, obs_mode: str, control_mode: str, meta: dict) -> Path | None:
    """Name the task's own env id (module-qualified) in the json of the file ManiSkill's replay
    wrote from ``traj_path``: its RecordEpisode records the bare id gymnasium made (and, from a suite's
    id, no task). The path is ManiSkill's naming, ``<name>.<obs_mode>.<control_mode>.physx_cpu``."""
    src = Path(traj_path)
    out = src.parent / f"{src.stem.split('.')[0]}.{obs_mode}.{control_mode}.physx_cpu.json"
    if not out.exists():
        return None
    suite, task_id = parse_env_id(meta["env_info"]["env_id"])
    task_id = meta["env_info"]["env_kwargs"].get("task_id", 0) if task_id is None else task_id
    written = read_json(out)
    written["env_info"]["env_id"] = recorded_env_id(suite, int(task_id))
    atomic_write_json(out, written)
    return out.with_suffix(".h5")


def upgrade(paths: list[str]) -> None:
    """``--upgrade-gripper FILE.h5 ...``: convert version-1 trajectories in place
    (:func:`mani_skill_softvt.data.trajectory.upgrade_gripper_actions`)."""
    if not paths:
        _refuse(f"{UPGRADE_COMMAND} needs the trajectory files (.h5) to convert")
    for p in paths:
        try:
            n = upgrade_gripper_actions(Path(p))
        except (OSError, ValueError) as e:  # OSError: CorruptDataError and FileNotFoundError name the file
            _refuse(str(e))
        print(f"{p}: " + (f"{n} episodes converted to ManiSkill's normalised gripper action" if n else
                          "already current, left as it was"))


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--upgrade-gripper"]:
        return upgrade(argv[1:])

    args = replay_trajectory.parse_args(argv)
    if args.obs_mode is not None:
        try:
            ObsMode.parse(args.obs_mode)  # the env's modes, before ManiSkill makes an env
        except ValueError as e:
            _refuse(f"-o: {e}")
    meta = check_input(args.traj_path, args.target_control_mode)
    kwargs = meta["env_info"]["env_kwargs"]
    if args.target_control_mode is not None:
        if args.num_envs > 1:
            raise SystemExit("-c with -n > 1: SoftVT's conversions run in this process only; use -n 1 "
                             "(or convert once, then replay the converted file with -n)")
        _patch_conversion(replay_trajectory)
    replay_trajectory.main(args)
    if args.save_traj:
        record_task_env_id(args.traj_path, args.obs_mode or kwargs.get("obs_mode") or "state",
                           args.target_control_mode or kwargs.get("control_mode"), meta)


def cli() -> None:
    """The console command (``softvt-replay``)."""
    # ManiSkill's replay starts worker processes with -n > 1; Warp needs spawn (as ManiSkill's own tool does).
    mp.set_start_method("spawn", force=True)
    main(sys.argv[1:])


if __name__ == "__main__":
    cli()
