"""mani_skill_softvt: deformation-aware visuo-tactile manipulation tasks for ManiSkill3.

Layout (one concept, one place):

- ``physics/``     Newton FEM soft bodies, the SAPIEN <-> Newton coupling, the deformation metric
- ``assets/``      procedural meshes, tetrahedral meshes, asset cards, rigid twins, props
- ``tactile/``     GelSight Mini tactile sensor (Taxim-style optics, FOTS-style markers, ManiSkill sensor)
- ``tasks/``       the four task suites as ManiSkill environments, the Panda, suites and OOD factors
- ``calibration/`` the scripted grasp trial, per-object gripper envelope and deformation tolerance
- ``expert/``      scripted pick-and-place expert and its motion planner
- ``data/``        demonstration data: seed ranges, demo-set layout, ManiSkill trajectories, LeRobot export
- ``evaluation/``  R_t / R_max / DSR metrics, DSR wrapper, ID/OOD protocols, runner, reports, videos
"""

# First: the CPU dispatch of every library below is pinned before any of them loads (numerics.py).
from . import numerics  # noqa: E402

numerics.pin()

from .version import __version__  # noqa: E402,F401

from . import tasks  # noqa: E402,F401  (registers the four suites and SoftGraspLift-v1)
