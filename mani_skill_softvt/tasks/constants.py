"""Task-level constants: robot, gripper, scene geometry, episode limits (SI units)."""

import numpy as np

from ..physics.constants import CONTROL_FREQ, SIM_FREQ  # noqa: F401  (re-exported for tasks)

# Gripper: finger joint q is half the jaw gap. Open = 80 mm gap. The closed target is below
# zero (ManiSkill's trick) so that a closing drive always presses; the force limit caps it.
GRIPPER_Q_OPEN = 0.04
GRIPPER_Q_CLOSED = -0.01
GRIPPER_STIFFNESS = 1e3  # N/m (ManiSkill's default)
GRIPPER_DAMPING = 1e2  # N*s/m
GRIPPER_FORCE_LIMIT = 20.0  # N per finger

# Newton collider of each fingertip (the URDF's "rubber tip" box), in the finger link frame.
FINGERTIP_HALF_EXTENTS = (8.75e-3, 7.6e-3, 9.25e-3)
FINGERTIP_OFFSET = {"left": (0.0, 7.58e-3, 45.25e-3), "right": (0.0, -7.58e-3, 45.25e-3)}

# Robot base placement (as in ManiSkill's tabletop tasks), table top at z = 0.
ROBOT_BASE_POSE = np.array([-0.615, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
TABLE_HALF_EXTENTS = (0.6, 0.8, 0.025)

MAX_EPISODE_STEPS = 300

# Settling before an episode: the object is at rest when its fastest node is slower than this.
SETTLE_SPEED = 2e-3  # m/s
SETTLE_MAX_TIME = 1.0  # s

CAMERA_SIZE = 224  # policy camera resolution (SPEC section 4)
