"""The action contract: what an action of each SoftVT control mode means, in one place.

The control modes (``CONTROL_MODES``): the paper's ``pd_ee_pose`` (7-D: absolute TCP position in the
robot base frame, axis-angle orientation, gripper closure) and ManiSkill's ``pd_joint_pos``,
``pd_joint_delta_pos`` and ``pd_ee_delta_pose``, each with a ``_binary`` twin. The robot base frame
(``ROBOT_BASE_POSE``: the Panda's base in the world, translated only) is the frame a pose action is
in: :func:`ee_action` and :func:`base_frame_pose` turn world poses into actions.

The gripper, in two encodings per mode (``<mode>`` and ``<mode>_binary``) and two scales: the
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

Nothing here needs a simulator: a policy, a converter or a data file reads actions through this
module without importing ManiSkill's agent (:mod:`mani_skill_softvt.tasks.robot` builds the
controllers that execute them).
"""

from __future__ import annotations

import numpy as np

from ..physics.transforms import down_rotvec, quat_to_rotvec
from ..provenance import GRIPPER_ACTION_VERSION, GRIPPER_ACTION_VERSIONS, UPGRADE_COMMAND  # noqa: F401  (the contract's)

# The robot base in the world: [x, y, z, qw, qx, qy, qz] (translated only; base_frame_pose checks it).
ROBOT_BASE_POSE = np.array([-0.615, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
# Finger joint target (half the jaw gap, m) fully open and at the closed end of the drive.
GRIPPER_Q_OPEN = 0.04
GRIPPER_Q_CLOSED = -0.01

ARM_MODES = ("pd_ee_pose", "pd_joint_pos", "pd_joint_delta_pos", "pd_ee_delta_pose")
CONTROL_MODES = tuple(m for arm in ARM_MODES for m in (arm, f"{arm}_binary"))


def closure_to_q(closure):
    """Gripper closure g in [0, 1] -> finger joint target q (m). Works on floats and tensors."""
    return GRIPPER_Q_OPEN * (1 - closure) + GRIPPER_Q_CLOSED * closure  # exact at both ends


def q_to_closure(q):
    return (q - GRIPPER_Q_OPEN) / (GRIPPER_Q_CLOSED - GRIPPER_Q_OPEN)


# The gripper actions' encoding and its history: mani_skill_softvt/provenance/.
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
    return np.concatenate([position_world - ROBOT_BASE_POSE[:3], down_rotvec(yaw), [closure]]).astype(np.float32)


def base_frame_pose(tcp_pose_world: np.ndarray, rotvec_reference: np.ndarray | None = None) -> np.ndarray:
    """A world TCP pose (xyz, wxyz) as the action's pose: base-frame xyz and axis-angle (6,), the
    axis-angle on the branch nearest ``rotvec_reference`` (see ``quat_to_rotvec``)."""
    # The base is only translated from the world; checked so that a rotated base cannot silently
    # turn the pose into something no action reproduces.
    if not np.array_equal(ROBOT_BASE_POSE[3:], [1.0, 0.0, 0.0, 0.0]):
        raise NotImplementedError(f"the base-frame pose assumes an unrotated robot base, got {ROBOT_BASE_POSE}")
    pose = np.asarray(tcp_pose_world, np.float64).reshape(7)
    return np.concatenate([pose[:3] - ROBOT_BASE_POSE[:3], quat_to_rotvec(pose[3:7], reference=rotvec_reference)])
