"""The Panda used by every SoftVT task: absolute end-effector pose control and a force-limited gripper.

Differences from ManiSkill's ``panda`` (same URDF and arm gains):
- the gripper drive is force-limited (``GRIPPER_FORCE_LIMIT``), so a full "close" stops where
  the soft object pushes back instead of driving through it;
- the 7-D action of the paper's policies: absolute end-effector position and axis-angle orientation
  in the robot base frame (task-space differential IK), then one gripper value. ManiSkill's own
  ``pd_ee_pose`` reads those three rotation numbers as XYZ Euler angles; here they are the
  axis-angle the paper (and the openpi/LIBERO action) means, so a top-down hand turned by a yaw
  is pi * (cos(yaw/2), sin(yaw/2), 0) and not a hand tilted by tens of degrees;
- beside it, the control modes a ManiSkill user reaches for: ``pd_joint_pos`` (what ManiSkill's
  motion planners drive; arm joint targets), ``pd_joint_delta_pos`` and ``pd_ee_delta_pose``
  (ManiSkill's normalised delta modes, what its learning baselines train on), all with ManiSkill
  Panda's arm gains and bounds;
- the gripper, in two encodings per mode (``<mode>`` and ``<mode>_binary``) and two scales: the
  paper's ``pd_ee_pose`` commands a closure, ManiSkill's modes (joint and delta) the normalised
  action of ManiSkill's Panda, so its baselines, replay conversions and motion planners see what
  they expect:

  ===========================  ===============================================  ==========================
  mode                          ``<mode>``                                       ``<mode>_binary``
  ===========================  ===============================================  ==========================
  ``pd_ee_pose``                closure g in [0, 1] (0 open 80 mm, 1 closed)     < 0.5 open, >= 0.5 close
  ``pd_joint_pos``,             a in [-1, 1], ManiSkill's Panda's scale          > 0 open, <= 0 close
  ``pd_joint_delta_pos``,       (1 open 80 mm, -1 closed): a = 1 - 2 g           (ManiSkill's +1 / -1)
  ``pd_ee_delta_pose``
  ===========================  ===============================================  ==========================

  Both scales map linearly onto the same finger joint target q (half the jaw gap):
  q = (1 - g) * GRIPPER_Q_OPEN + g * GRIPPER_Q_CLOSED; ManiSkill's Panda has the same joint range.
  "close" drives to the closed end until the force limit stops it. :func:`gripper_action` and
  :func:`action_closure` convert between the two.
"""

from __future__ import annotations

from copy import deepcopy
from dataclasses import dataclass, fields

import numpy as np
import torch
from gymnasium import spaces
from mani_skill.agents.controllers import (PDEEPoseController, PDEEPoseControllerConfig, PDJointPosMimicController,
                                           PDJointPosMimicControllerConfig)
from mani_skill.agents.registration import register_agent
from mani_skill.utils.common import to_numpy
from mani_skill.utils.gym_utils import clip_and_scale_action
from mani_skill.agents.robots.panda.panda import Panda
from mani_skill.utils.geometry.rotation_conversions import axis_angle_to_quaternion
from mani_skill.utils.structs.pose import Pose

from ..physics.transforms import down_rotvec, quat_to_rotvec
from . import constants as C


ARM_MODES = ("pd_ee_pose", "pd_joint_pos", "pd_joint_delta_pos", "pd_ee_delta_pose")
CONTROL_MODES = tuple(m for arm in ARM_MODES for m in (arm, f"{arm}_binary"))


def closure_to_q(closure):
    """Gripper closure g in [0, 1] -> finger joint target q (m). Works on floats and tensors."""
    return C.GRIPPER_Q_OPEN * (1 - closure) + C.GRIPPER_Q_CLOSED * closure  # exact at both ends


def q_to_closure(q):
    return (q - C.GRIPPER_Q_OPEN) / (C.GRIPPER_Q_CLOSED - C.GRIPPER_Q_OPEN)


# Version of the gripper actions' encoding, recorded in every trajectory file's env kwargs
# (``gripper_action_version``). 1 (files without the kwarg): the closure in [0, 1] in every mode;
# 2: ManiSkill's normalised action in the joint and delta modes, the closure in pd_ee_pose.
GRIPPER_ACTION_VERSION = 2
UPGRADE_COMMAND = "python -m mani_skill_softvt.replay --upgrade-gripper"
GRIPPER_ACTION_VERSIONS = {  # why an older version is refused; {path}: the file
    1: "its joint- or delta-mode gripper actions are closures in [0, 1] (written before mani_skill_softvt used "
       "ManiSkill's normalised gripper action in [-1, 1] in those modes); convert the file in place with "
       f"`{UPGRADE_COMMAND} {{path}}`, then run this again",
}

# The paper's mode: its gripper action is the closure itself. Every other arm mode is ManiSkill's and
# takes ManiSkill's normalised gripper action.
CLOSURE_ARM_MODES = ("pd_ee_pose",)


def normalized_gripper(control_mode: str) -> bool:
    """Whether ``control_mode``'s gripper action is ManiSkill's normalised one ([-1, 1], 1 open)
    rather than the closure in [0, 1] (``pd_ee_pose`` and ``pd_ee_pose_binary``)."""
    arm = control_mode.removesuffix("_binary")
    if arm not in ARM_MODES:
        raise ValueError(f"unknown control mode '{control_mode}'; choose one of {CONTROL_MODES}")
    return arm not in CLOSURE_ARM_MODES


def gripper_action(closure, control_mode: str):
    """The gripper action of ``control_mode`` that commands ``closure`` (g in [0, 1]); a ``_binary``
    mode's command is "close" for any g > 0 (what the expert's calibrated grasp means), else "open".
    Works on floats and arrays."""
    g = np.asarray(closure, np.float32)
    if control_mode.endswith("_binary"):
        g = (g > 0.0).astype(np.float32)
    return (np.float32(1.0) - np.float32(2.0) * g) if normalized_gripper(control_mode) else g


def action_closure(value, control_mode: str):
    """The closure g in [0, 1] (a ``_binary`` mode's: 0 or 1) that ``control_mode``'s gripper action
    ``value`` commands: the inverse of :func:`gripper_action`. Works on floats and arrays."""
    v = np.asarray(value, np.float32)
    if control_mode.endswith("_binary"):
        closed = v <= 0.0 if normalized_gripper(control_mode) else v >= 0.5
        return closed.astype(np.float32)
    return np.float32(0.5) * (np.float32(1.0) - v) if normalized_gripper(control_mode) else v


def ee_action(position_world: np.ndarray, closure: float, yaw: float = 0.0) -> np.ndarray:
    """``pd_ee_pose`` action of the top-down hand: TCP position (world, converted to the robot base
    frame), the axis-angle of the hand turned by ``yaw``, the gripper closure."""
    return np.concatenate([position_world - C.ROBOT_BASE_POSE[:3], down_rotvec(yaw), [closure]]).astype(np.float32)


def base_frame_pose(tcp_pose_world: np.ndarray, rotvec_reference: np.ndarray | None = None) -> np.ndarray:
    """A world TCP pose (xyz, wxyz) as the action's pose: base-frame xyz and axis-angle (6,), the
    axis-angle on the branch nearest ``rotvec_reference`` (see ``quat_to_rotvec``)."""
    # The base is only translated from the world; checked so that a rotated base cannot silently
    # turn the pose into something no action reproduces.
    if not np.array_equal(C.ROBOT_BASE_POSE[3:], [1.0, 0.0, 0.0, 0.0]):
        raise NotImplementedError(f"the base-frame pose assumes an unrotated robot base, got {C.ROBOT_BASE_POSE}")
    pose = np.asarray(tcp_pose_world, np.float64).reshape(7)
    return np.concatenate([pose[:3] - C.ROBOT_BASE_POSE[:3], quat_to_rotvec(pose[3:7], reference=rotvec_reference)])


def validate_action(action, shape: tuple[int, ...], control_mode: str):
    """Reject a malformed action before anything in the simulation changes; return it as ManiSkill
    takes it (arrays and tensors unchanged, sequences of numbers as float32 arrays). ``shape``:
    the control mode's action shape (unbatched)."""
    if action is None or isinstance(action, dict):
        return action
    a = np.asarray(to_numpy(action))
    if a.dtype.kind not in "fiu":
        raise ValueError(f"action must be numbers (7 floats: [x, y, z] position, [rx, ry, rz] axis-angle, "
                         f"gripper), got {type(action).__name__} of dtype {a.dtype}")
    if a.shape not in (tuple(shape), (1, *shape)):
        raise ValueError(f"action has shape {a.shape}, expected {tuple(shape)} for control mode '{control_mode}' "
                         "([x, y, z] position, [rx, ry, rz] axis-angle, gripper)")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action contains NaN or inf: {a.ravel().tolist()}")
    return action if isinstance(action, (np.ndarray, torch.Tensor)) else a.astype(np.float32)


def mid_height_grasp(nodes: np.ndarray) -> float:
    """TCP height that centres the pads on an object (its nodes), without the fingertips touching the table."""
    return float(max(C.MIN_GRASP_HEIGHT, 0.5 * (nodes[:, 2].min() + nodes[:, 2].max())))


class AxisAnglePoseController(PDEEPoseController):
    """ManiSkill's absolute end-effector pose controller with the orientation as an axis-angle
    (ManiSkill's reads XYZ Euler angles). Delta modes keep ManiSkill's own controller."""

    def compute_target_pose(self, prev_ee_pose_at_base, action):
        if self.config.use_delta:
            return super().compute_target_pose(prev_ee_pose_at_base, action)
        return Pose.create_from_pq(action[:, 0:3], axis_angle_to_quaternion(action[:, 3:6]))


@dataclass
class AxisAnglePoseControllerConfig(PDEEPoseControllerConfig):
    controller_cls = AxisAnglePoseController


class ClosureGripperController(PDJointPosMimicController):
    """Mimic finger controller commanded by a closure g in [0, 1] (or a binary open/close), or, with
    ``normalized``, by ManiSkill's Panda's normalised action in [-1, 1] (1 open, -1 closed)."""

    config: "ClosureGripperControllerConfig"

    def _initialize_action_space(self):
        low = -1.0 if self.config.normalized else 0.0
        self.single_action_space = spaces.Box(np.full(1, low, np.float32), np.ones(1, np.float32), dtype=np.float32)

    def set_action(self, action):
        a = torch.as_tensor(action, dtype=torch.float32, device=self.device)
        if self.config.normalized:
            if self.config.binary:
                q = torch.where(a <= 0.0, C.GRIPPER_Q_CLOSED, C.GRIPPER_Q_OPEN)
            else:
                q = clip_and_scale_action(a, C.GRIPPER_Q_CLOSED, C.GRIPPER_Q_OPEN)  # as ManiSkill's Panda scales it
        else:
            # The paper's closure: unchanged arithmetic (pd_ee_pose records and policies depend on its bits).
            g = (a >= 0.5).float() if self.config.binary else a.clamp(0.0, 1.0)
            q = closure_to_q(g)
        # The parent's action is the finger target q itself (normalize_action=False).
        super().set_action(q)


@dataclass
class ClosureGripperControllerConfig(PDJointPosMimicControllerConfig):
    controller_cls = ClosureGripperController
    binary: bool = False
    normalized: bool = False  # ManiSkill's [-1, 1] action (joint and delta modes) instead of the closure


@register_agent(override=True)
class PandaSoftVT(Panda):
    uid = "panda_softvt"
    gripper_stiffness = C.GRIPPER_STIFFNESS
    gripper_damping = C.GRIPPER_DAMPING
    gripper_force_limit = C.GRIPPER_FORCE_LIMIT

    @property
    def _controller_configs(self):
        panda = super()._controller_configs
        arms = {mode: deepcopy(panda[mode]["arm"]) for mode in ARM_MODES}
        arms["pd_ee_pose"] = AxisAnglePoseControllerConfig(**{
            f.name: getattr(arms["pd_ee_pose"], f.name) for f in fields(PDEEPoseControllerConfig)
            if f.name != "controller_cls" and f.init})
        configs = {}
        for arm_mode, arm in arms.items():
            for mode, binary in ((arm_mode, False), (f"{arm_mode}_binary", True)):
                gripper = ClosureGripperControllerConfig(
                    self.gripper_joint_names,
                    lower=C.GRIPPER_Q_CLOSED,
                    upper=C.GRIPPER_Q_OPEN,
                    stiffness=self.gripper_stiffness,
                    damping=self.gripper_damping,
                    force_limit=self.gripper_force_limit,
                    normalize_action=False,
                    mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}},
                    binary=binary,
                    normalized=normalized_gripper(mode),
                )
                configs[mode] = dict(arm=deepcopy(arm), gripper=gripper)
        return configs
