"""Constants of the calibration protocol (paper section 3.5; SPEC section 6)."""

import numpy as np

# Closures swept from loose to tight, and trials per closure (each with its own pose jitter).
CLOSURES = tuple(np.round(np.arange(0.10, 1.0001, 0.05), 2).tolist())
REPEATS = 3
PERCENTILE = 90.0

# Quick mode (tests, smoke runs): one asset, a few closures, one repeat.
QUICK_REPEATS = 1

# Slip: motion of the object's centroid relative to the hand (TCP frame) over the hold.
# A held object creeps ~0.1 mm over 2 s; a slipping one slides centimetres. 3 mm separates them.
SLIP_THRESHOLD = 3e-3  # m
# The object must end the hold this far above the table (it was lifted ~10 cm).
LIFT_THRESHOLD = 0.05  # m

# Phase lengths of one grasp-lift-hold trial, control steps at 20 Hz (hold: the paper's 2 s).
STEPS = {"approach": 10, "descend": 15, "close": 15, "lift": 20, "hold": 40}

# Pose jitter per repeat: TCP xy offset and gripper yaw relative to the object's yaw.
JITTER_XY = 2e-3  # m
JITTER_YAW = np.deg2rad(5.0)

SEED_BASE = 10_000  # calibration seeds never collide with demo (0..) or evaluation seeds
