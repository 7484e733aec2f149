"""Physics constants of the SAPIEN <-> Newton coupling (SI units).

Values were measured on this project's 2-core CPU machines unless noted (docs/physics.md).
"""

import numpy as np

from .config import DEFAULT_PHYSICS

# The settings that shape a soft grasp (lockstep rate, VBD schedule, contact, friction) are one
# frozen config, physics/config.py: an env is built with one, and records its signature.
SIM_FREQ = DEFAULT_PHYSICS.sim_freq  # the default lockstep rate, for readers of timing (an env's own: env.physics)
CONTROL_FREQ = 20

# Health check (a blow-up ends the episode).
MAX_PARTICLE_SPEED = 5.0  # m/s: nothing in a tabletop pick-and-place moves this fast
# A tet squashed to 2 % of its rest volume or less counts as collapsed: scored, not raised (evaluation/metrics.py).
MIN_TET_VOLUME_RATIO = 0.02

IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])  # SAPIEN order [p, q_wxyz]

# Objects spawn this far above their support (plus the node contact radius) and settle down.
SPAWN_CLEARANCE = 0.5e-3

# PhysX solver position iterations of a rigid twin (SAPIEN's default is 15). At 15 the resting
# contact of a twin made of several convex parts does not converge: the pastry010 twin crept at
# 2-3 mm/s (0.05 rad/s) through a whole second of damped settling; at 40 it rests (< 0.7 mm/s).
RIGID_SOLVER_POSITION_ITERATIONS = 40
