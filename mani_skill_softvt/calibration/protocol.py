"""Constants of the calibration protocol (paper section 3.5)."""

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

# The paper's cards (its calibration table), for the comparison in docs/calibration.md: g_min, g_max, span mm, tau_o % diag.
PAPER_CARDS = {
    "soft_pastry001": (0.4000, 0.8000, 26.21, 7.6),
    "soft_pastry002": (0.6547, 0.6900, 2.56, 9.3),
    "soft_pastry003": (0.4400, 0.8000, 13.26, 8.6),
    "soft_pastry005": (0.4700, 0.5800, 5.87, 10.7),
    "soft_pastry010": (0.4200, 0.6600, 24.82, 8.3),
    "soft_pastry011": (0.4400, 0.5800, 10.63, 7.1),
    "soft_stw_cube_hq": (0.3200, 0.6200, 19.43, 11.2),
    "soft_stw_cuboid_hq": (0.3800, 0.4400, 10.95, 9.8),
    "soft_stw_cylinder_hq": (0.2900, 0.6600, 21.95, 9.8),
    "soft_stw_sphere_hq": (0.3700, 0.6300, 20.77, 9.7),
}
