"""Task-level constants: robot, gripper, scene geometry, episode limits (SI units)."""

import numpy as np

from ..contracts.actions import GRIPPER_Q_CLOSED, GRIPPER_Q_OPEN, ROBOT_BASE_POSE  # noqa: F401  (the action contract's)
from ..physics.constants import CONTROL_FREQ, SIM_FREQ  # noqa: F401  (re-exported for tasks)

# Gripper: finger joint q is half the jaw gap. Open = 80 mm gap. The closed target is below
# zero (ManiSkill's trick) so that a closing drive always presses; the force limit caps it (both
# targets are the action contract's, mani_skill_softvt/contracts/actions.py, as is the robot base pose).
# Soft drive: the force grows over most of the closure range (contact at g ~ 0.35 on a 45 mm
# object, the limit reached at g ~ 0.85), so a continuous closure grades the squeeze.
GRIPPER_STIFFNESS = 4e2  # N/m
GRIPPER_DAMPING = 1e2  # N*s/m: closing speed <= limit / damping = 0.1 m/s
# Grasp force per finger. 10 N holds every asset (2 * mu * N >> m * g even at mass x2.5) and
# keeps a binary close inside the FEM's valid range on the softest asset at modulus x0.5.
GRIPPER_FORCE_LIMIT = 10.0
FINGER_EFFECTIVE_MASS = 1.0  # kg: reflected inertia of the geared finger drive (see SoftBodyEnv)

# Newton collider of each fingertip (the URDF's "rubber tip" box), in the finger link frame.
FINGERTIP_HALF_EXTENTS = (8.75e-3, 7.6e-3, 9.25e-3)
FINGERTIP_OFFSET = {"left": (0.0, 7.58e-3, 45.25e-3), "right": (0.0, -7.58e-3, 45.25e-3)}
# The GelSight gel covers the fingertip pad: half extents across the finger (image columns) and
# along it (rows): 17.5 x 18.5 mm, longer than the 14.2 mm view, so part of its load is out of view.
GEL_PAD_HALF_EXTENTS = (FINGERTIP_HALF_EXTENTS[0], FINGERTIP_HALF_EXTENTS[2])

# The table, its top at z = 0 (the robot base's placement, as in ManiSkill's tabletop tasks, is the
# action contract's ROBOT_BASE_POSE).
TABLE_HALF_EXTENTS = (0.6, 0.8, 0.025)

MAX_EPISODE_STEPS = 300

# Settling before an episode: the object is at rest when its fastest node is slower than this.
SETTLE_SPEED = 2e-3  # m/s
# The loop stops as soon as everything is slower than SETTLE_SPEED (0.1-0.35 s for most layouts);
# a faceted ball twin on a marginal face rolls onto the next one under the damping for ~2.5 s.
SETTLE_MAX_TIME = 3.0  # s
SETTLE_VELOCITY_DAMPING = 0.9  # per 240 Hz tick while settling: e-folding time ~40 ms

CAMERA_SIZE = 224  # policy camera resolution (the paper's 224x224 views; observations.NATIVE_CAMERA_SIZE)

# ---------------------------------------------------------------- SoftVTBench suites
# Robot rest configuration (ManiSkill's tabletop default) and its per-joint init noise (rad).
ROBOT_REST_QPOS = np.array([0.0, np.pi / 8, 0.0, -np.pi * 5 / 8, 0.0, np.pi * 3 / 4, np.pi / 4, GRIPPER_Q_OPEN, GRIPPER_Q_OPEN])
ROBOT_INIT_QPOS_NOISE = 0.02

# Per-suite supports (m, world frame, table top z = 0; the robot base is at x = -0.615 facing +x,
# so +y is the robot's left). Ranges are half-widths of uniform boxes around the centres.
LAYOUTS = {
    # Object suites: one object on the robot's left, the basket on its right.
    "basket": {"object_center": (-0.07, 0.11), "object_half_range": (0.03, 0.03),
               "target_center": (0.0, -0.14), "target_half_range": (0.02, 0.02)},
    # Spatial suites: two instances side by side (centre of the pair), the plate beyond them.
    "plate": {"object_center": (-0.10, 0.0), "object_half_range": (0.02, 0.02),
              "target_center": (0.08, 0.0), "target_half_range": (0.02, 0.03)},
}
SPATIAL_HALF_GAP = 0.09  # m: each instance's offset from the pair's centre (62 mm objects, 80 mm jaw)
OBJECT_YAW_RANGE = np.pi / 12
# The difficulty study scales the placement ranges (reset option placement_scale) up to twice: the
# doubled Object-Soft ranges keep the object 0.17 m or more from the basket's centre and inside the
# expert's reach (its doubled-range episodes are the study's check); larger ones are not verified.
MAX_PLACEMENT_SCALE = 2.0

# Success and failure predicates.
REST_SPEED = 0.02  # m/s: centroid speed below which an object is at rest
REGION_Z_TOLERANCE = 0.005  # m: the lowest node may sit this far below the region's floor (node radius, sag)
GRASP_MIN_FORCE = 0.5  # N on each pad: a grasp, not a graze
GRASP_CENTROID_DISTANCE = 0.05  # m: the grasped object's centroid is this close to the TCP
DROP_SPEED = 0.25  # m/s downward while not held: free fall from >3 mm, never a settling object
OFF_TABLE_DEPTH = 0.02  # m below the table top

# Lighting: the paper's dome light intensity; every light is scaled by intensity / nominal.
NOMINAL_LIGHT_INTENSITY = 135.0

# Cameras (policy views at CAMERA_SIZE): third-person and wrist (on the hand, looking along the
# fingers; SAPIEN cameras look along their +x).
BASE_CAMERA_EYE = (0.32, 0.0, 0.38)
BASE_CAMERA_TARGET = (-0.05, 0.0, 0.0)
BASE_CAMERA_FOV = np.deg2rad(62)
WRIST_CAMERA_OFFSET = (0.0465, 0.0, 0.036)  # hand frame: where the RealSense sits on ManiSkill's wrist-camera Panda
WRIST_CAMERA_Q = (0.7071068, 0.0, -0.7071068, 0.0)  # wxyz: camera +x -> hand +z (along the fingers)
RENDER_CAMERA_EYE = (0.35, 0.45, 0.4)
RENDER_CAMERA_TARGET = (-0.05, 0.0, 0.05)
# Lowest TCP height for a grasp: the pad's half height (9.25 mm) plus 2.75 mm clearance.
MIN_GRASP_HEIGHT = 0.012
