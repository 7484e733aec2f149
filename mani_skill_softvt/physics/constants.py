"""Physics constants of the SAPIEN <-> Newton coupling (SI units).

Values were measured on this project's 2-core CPU machines unless noted (docs/physics.md).
"""

import numpy as np

# Lockstep rate: SAPIEN and Newton both step at SIM_FREQ, one Newton step per SAPIEN step.
# 100 Hz with Newton substeps was unstable (15 g fingers, one-step-late contact forces).
SIM_FREQ = 240
CONTROL_FREQ = 20

# Newton substeps per lockstep tick and VBD iterations per substep. VBD is a Gauss-Seidel
# solver: with E ~ 5e4 Pa and ~8 mm elements a node's elastic stiffness is ~60x its inertia
# m/dt^2 at 240 Hz, and under-converged iterations create spurious net forces (a resting cube
# drifts sideways). Substepping raises m/dt^2 by substeps^2, which converges far better than
# more iterations.
NEWTON_SUBSTEPS = 4
VBD_ITERATIONS = 5
# Stiff FEM bodies (E >= STIFF_MODULUS, e.g. hard rubber; the package's rigid twins are PhysX rigid
# bodies and never reach Newton) get more substeps, not more iterations: a node's elastic stiffness
# scales with E and its inertia m/h^2 with substeps^2, so x5 stiffer bodies need ~sqrt(5) x the
# substeps to converge like the soft assets. At 4 x 10 a 20 g bun (FEM, x5 stiff) held by
# 2 x 1 N of pad force (9x its weight at mu 0.9) still slid out during transport; at 8 x 5 (the same
# 40 sweeps per tick) it holds, and 4 x 20 holds at 1.7x the wall time (measured).
STIFF_MODULUS = 2.5e5  # Pa
NEWTON_SUBSTEPS_STIFF = 8
# Friction smoothing velocity [m/s]: below it VBD's Coulomb friction is a viscous drag, so a
# resting or held object creeps. 1e-2 let a held object creep ~1 mm/s; at 1e-3 a resting cube
# crept 0.139 mm/s, at 1e-4 0.024 mm/s with the same cost and the calibration grasp's peak D
# within 2 % (benchmarks/bench_vbd_schedule.py).
FRICTION_EPSILON = 1e-4

# Particle-collider contact (penalty) stiffness [N/m] and damping, per contact point.
SOFT_CONTACT_KE = 5.0e3
SOFT_CONTACT_KD = 1.0e-2
# Contact radius of FEM nodes [m]; Newton's default (0.1 m) would make 10 cm thick skins.
PARTICLE_RADIUS = 1.0e-3
# Contact detection margin [m].
SOFT_CONTACT_GAP = 4.0e-3

# Health check (a blow-up ends the episode).
MAX_PARTICLE_SPEED = 5.0  # m/s: nothing in a tabletop pick-and-place moves this fast
# A tet squashed to 2 % of its rest volume or less counts as collapsed: scored, not raised (evaluation/metrics.py).
MIN_TET_VOLUME_RATIO = 0.02

IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])  # SAPIEN order [p, q_wxyz]

# Friction coefficients of the colliders (VBD mixes them with the object's own).
FINGER_FRICTION = 1.2  # rubber pads (the paper uses dynamic mu = 1.2 on the fingers)
TABLE_FRICTION = 0.6
# Objects spawn this far above their support (plus the node contact radius) and settle down.
SPAWN_CLEARANCE = 0.5e-3

# PhysX solver position iterations of a rigid twin (SAPIEN's default is 15). At 15 the resting
# contact of a twin made of several convex parts does not converge: the pastry010 twin crept at
# 2-3 mm/s (0.05 rad/s) through a whole second of damped settling; at 40 it rests (< 0.7 mm/s).
RIGID_SOLVER_POSITION_ITERATIONS = 40


# How the hand's orientation in a pd_ee_pose action is read: 1.0 the axis-angle the paper means
# (tasks.robot.AxisAnglePoseController). Cards and demos made while ManiSkill's controller read it
# as XYZ Euler angles (a scripted grasp at 20 deg of yaw then came down tilted by ~30 deg) lack it.
EE_ORIENTATION_AXIS_ANGLE = 1.0

# The constants above that shape a soft grasp; a calibration card and its sweep log record them,
# so a card made under other physics is refused instead of scoring with a stale tolerance.
SIGNATURE_NAMES = ("SIM_FREQ", "NEWTON_SUBSTEPS", "VBD_ITERATIONS", "STIFF_MODULUS", "NEWTON_SUBSTEPS_STIFF",
                   "FRICTION_EPSILON", "SOFT_CONTACT_KE", "SOFT_CONTACT_KD", "PARTICLE_RADIUS", "SOFT_CONTACT_GAP",
                   "FINGER_FRICTION", "TABLE_FRICTION", "EE_ORIENTATION_AXIS_ANGLE")


def physics_signature() -> dict:
    """The grasp-shaping constants as they are now (read at call time: benchmarks override them)."""
    values = globals()
    return {name: float(values[name]) for name in SIGNATURE_NAMES}


def signature_mismatch(recorded) -> list[str]:
    """Human-readable differences between a recorded signature and the current physics."""
    if not isinstance(recorded, dict):
        return ["no physics signature recorded (made before signatures existed)"]
    now = physics_signature()
    return [f"{k}: recorded {recorded.get(k)!r}, now {v!r}" for k, v in now.items() if recorded.get(k) != v]
