"""ManiSkill's ``replay_trajectory`` on SoftVT trajectories: ``python -m mani_skill_softvt.replay``.

Every flag is ManiSkill's own, handed over unchanged (``--traj-path``, ``-o``, ``-c``,
``--use-env-states``, ``--use-first-env-state``, ``--save-traj``, ``--save-video``, ``-n`` ...;
``--help`` lists them)::

    python -m mani_skill_softvt.replay --traj-path demos/sample/object_soft/task3.h5 \\
        --use-env-states -o rgb+tactile --save-traj
    python -m mani_skill_softvt.replay --traj-path FILE.h5 -c pd_ee_delta_pose -o rgb --save-traj

Output goes beside the input as ``<name>.<obs_mode>.<control_mode>.physx_cpu.h5`` + ``.json``
(ManiSkill's naming). Files recorded by this package name their env as
``mani_skill_softvt:<env id>``, so ``python -m mani_skill.trajectory.replay_trajectory`` itself
replays them too; this entry adds what ManiSkill's converter cannot know (``-c`` from
``pd_joint_pos``, the mode motion-planning demos are recorded in):

- into ``pd_ee_pose`` / ``pd_ee_pose_binary``: SoftVT's absolute pose is an axis-angle, while
  ManiSkill's converter writes XYZ Euler angles. Each step's target is the TCP pose of the
  recorded joint target (forward kinematics), as ManiSkill's converter aims at the target and
  not at the lagging arm;
- into any ``*_binary`` mode (``pd_joint_pos_binary`` included, which ManiSkill does not convert to): a recorded closure g in [0, 1] becomes "close" (1) when g > 0, else
  "open" (0); ManiSkill would copy g, and a calibrated closure below 0.5 would read as "open".
"""

from __future__ import annotations

import multiprocessing as mp
import sys
import types

import numpy as np


def binary_gripper(action) -> np.ndarray:
    """An action with its last entry (the gripper closure) as the binary command: 1 if > 0."""
    a = np.array(action, dtype=np.float32, copy=True)
    a[..., -1] = (a[..., -1] > 0.0).astype(np.float32)
    return a


class _BinaryGripperEnv:
    """The env a converter steps, with every action's gripper made binary on the way in."""

    def __init__(self, env):
        self._env = env

    def step(self, action):
        return self._env.step(binary_gripper(np.asarray(action.cpu() if hasattr(action, "cpu") else action)))

    def __getattr__(self, name):
        return getattr(self._env, name)


def joint_pos_to_ee_pose(output_mode, ori_actions, ori_env, env, render=False, pbar=None, verbose=False) -> dict:
    """Replay ``pd_joint_pos`` actions in ``env`` (``pd_ee_pose``, axis-angle): per step the TCP
    pose (robot base frame) that the recorded arm joint target reaches, and the recorded gripper.
    The signature is ManiSkill's converters'; ``ori_env`` is not stepped (the target is the action)."""
    from .physics.transforms import quat_to_rotvec

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
        _, _, _, _, info = env.step(np.concatenate([p, rotvec, [a[-1]]]).astype(np.float32))
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
            env = _BinaryGripperEnv(env)
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


def main(argv: list[str] | None = None) -> None:
    import mani_skill_softvt  # noqa: F401  (registers the SoftVT envs before ManiSkill makes one)
    from mani_skill.trajectory import replay_trajectory

    args = replay_trajectory.parse_args(argv)
    if args.target_control_mode is not None:
        if args.num_envs > 1:
            raise SystemExit("-c with -n > 1: SoftVT's conversions run in this process only; use -n 1 "
                             "(or convert once, then replay the converted file with -n)")
        _patch_conversion(replay_trajectory)
    replay_trajectory.main(args)


def cli() -> None:
    """The console command (``softvt-replay``)."""
    # ManiSkill's replay starts worker processes with -n > 1; Warp needs spawn (as ManiSkill's own tool does).
    mp.set_start_method("spawn", force=True)
    main(sys.argv[1:])


if __name__ == "__main__":
    cli()
