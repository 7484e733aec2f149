"""Per-object calibration (paper section 3.5): the scripted grasp-lift-hold trial, closure sweeps,
the gripper envelope and tolerance statistics, calibration cards and their plots."""
