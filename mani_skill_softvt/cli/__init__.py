"""The commands: argument parsing and output, each calling the library (README, "Commands").

- :mod:`.evaluate` (``softvt-evaluate``): TSR and DSR of a policy under a protocol; ``--rescore``,
  ``--reproduce``;
- :mod:`.compare` (``softvt-compare``): two recipes over their training seeds, by the
  pre-registered seed-level rule;
- :mod:`.gallery` (``softvt-gallery``): the asset and tactile galleries of the documentation;
- :mod:`.warmup` (``softvt-warmup``): the Warp kernel cache;
- :mod:`.grasp_demo`: the calibration's scripted grasp as a video.

Each keeps its old path (``python -m mani_skill_softvt.evaluate`` ...) as an alias for one release.
The calibration and demo commands (``calibrate.py``, ``demos.py``) still hold their library beside
their parsing at the package root; the ManiSkill, LeRobot and openpi commands live with their
integrations (``integrations/``), the campaign's with the campaign (``campaign/``).
"""
