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
- the gripper, in two encodings per mode and two scales (:mod:`mani_skill_softvt.contracts.actions`, the action
  contract: the control modes, the gripper's encodings, the robot base frame).
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

from ..contracts.actions import ARM_MODES, closure_to_q, normalized_gripper
from . import constants as C


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
