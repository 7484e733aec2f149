"""mani_skill_softvt: deformation-aware visuo-tactile manipulation tasks for ManiSkill3.

Layout (one concept, one place):

- ``physics/``     Newton FEM soft bodies, the SAPIEN <-> Newton coupling, the deformation metric
- ``assets/``      procedural meshes, tetrahedral meshes, asset cards, rigid twins, props
- ``tactile/``     GelSight Mini tactile sensor (Taxim-style optics, FOTS-style markers)
- ``tasks/``       the four task suites as ManiSkill environments
- ``calibration/`` per-object gripper envelope and deformation tolerance
- ``expert/``      scripted expert and demonstration dataset
- ``evaluation/``  DSR wrapper, ID/OOD protocols, reports
"""

__version__ = "0.1.0"

from . import tasks  # noqa: E402,F401  (registers the four suites and SoftGraspLift-v1)
