"""The Panda used by every SoftVT task: absolute end-effector pose control and a force-limited gripper.

Differences from ManiSkill's ``panda`` (same URDF and arm gains):
- the gripper drive is force-limited (``GRIPPER_FORCE_LIMIT``), so a full "close" stops where
  the soft object pushes back instead of driving through it;
- the default control mode is ``pd_ee_pose``: absolute end-effector position and axis-angle
  orientation in the robot base frame (task-space differential IK), plus one gripper value.
"""

from __future__ import annotations

from copy import deepcopy

from mani_skill.agents.controllers import PDJointPosMimicControllerConfig
from mani_skill.agents.registration import register_agent
from mani_skill.agents.robots.panda.panda import Panda

from . import constants as C


@register_agent(override=True)
class PandaSoftVT(Panda):
    uid = "panda_softvt"
    gripper_stiffness = C.GRIPPER_STIFFNESS
    gripper_damping = C.GRIPPER_DAMPING
    gripper_force_limit = C.GRIPPER_FORCE_LIMIT

    @property
    def _controller_configs(self):
        configs = deepcopy(super()._controller_configs)
        gripper = PDJointPosMimicControllerConfig(
            self.gripper_joint_names,
            lower=C.GRIPPER_Q_CLOSED,
            upper=C.GRIPPER_Q_OPEN,
            stiffness=self.gripper_stiffness,
            damping=self.gripper_damping,
            force_limit=self.gripper_force_limit,
            normalize_action=False,  # the action is the finger joint target q (half the jaw gap)
            mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}},
        )
        for mode in configs.values():
            mode["gripper"] = gripper
        return configs
