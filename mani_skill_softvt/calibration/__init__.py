"""Per-object calibration (paper section 3.5), the pure part the tasks read: the protocol's
constants, the gripper envelope and tolerance statistics, calibration cards and their plots.
The trials that drive the simulator (the scripted grasp-lift-hold of
:mod:`mani_skill_softvt.expert.grasp_script`, closure sweeps) are run by
:mod:`mani_skill_softvt.expert.calibration_trials` (the command: ``python -m mani_skill_softvt.calibrate``)."""
