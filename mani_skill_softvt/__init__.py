"""mani_skill_softvt: deformation-aware visuo-tactile manipulation tasks for ManiSkill3.

Layout (one concept, one place; README's "Layout" table):

- ``provenance/``     version markers, the record seal, ``UPGRADES``; the pinned numerics; the stack
- ``contracts/``      what env, policies, files and evaluator share: observations, actions, the policy
- ``assets/``         procedural meshes, tetrahedral meshes, asset cards, rigid twins, props
- ``physics/``        Newton FEM soft bodies, the SAPIEN <-> Newton coupling, the deformation metric
- ``tactile/``        GelSight Mini tactile sensor (Taxim-style optics, FOTS-style markers, ManiSkill sensor)
- ``calibration/``    calibration cards: the protocol, gripper envelope and deformation tolerance statistics
- ``tasks/``          the four task suites as ManiSkill environments, the Panda, suites and OOD factors
- ``expert/``         scripted pick-and-place expert, its motion planner, the calibration's grasp trials
- ``data/``           demonstration data's file formats: seed ranges, demo-set layout, trajectories
- ``evaluation/``     R_t / R_max / DSR metrics, DSR wrapper, ID/OOD protocols, runner, reports, videos
- ``demonstrations/`` expert demos recorded, screened, rendered, summarised
- ``rollout.py``      the one episode loop
- ``integrations/``   ManiSkill's tools, LeRobot, openpi (the library never imports them)
- ``cli/``            the commands (argument parsing and output)

The baselines and the studies are the campaign's own distribution (``campaign/softvt_campaign``).
"""

# First: the CPU dispatch of every library below is pinned before any of them loads (numerics.py).
from .provenance import numerics  # noqa: E402

numerics.pin()

from .version import __version__  # noqa: E402,F401

from . import tasks  # noqa: E402,F401  (registers the four suites and SoftGraspLift-v1)
