"""The commands: argument parsing and output, each calling the library (README, "Commands").

- :mod:`.evaluate` (``softvt-evaluate``): TSR and DSR of a policy under a protocol; ``--rescore``,
  ``--reproduce``;
- :mod:`.compare` (``softvt-compare``): two recipes over their training seeds, by the
  pre-registered seed-level rule;
- :mod:`.gallery` (``softvt-gallery``): the asset and tactile galleries of the documentation;
- :mod:`.warmup` (``softvt-warmup``): the Warp kernel cache;
- :mod:`.grasp_demo`: the calibration's scripted grasp as a video;
- :mod:`.calibrate` (``softvt-calibrate``): the per-object calibration cards;
- :mod:`.demos` (``softvt-demos``): expert demos generated, rendered, summarised, exported to LeRobot.

``python -m mani_skill_softvt.evaluate``, ``.calibrate`` and ``.demos`` stay (README's paths), thin
aliases of these; the others' old paths are aliases for one release. The ManiSkill, LeRobot and
openpi commands live with their integrations (``integrations/``), the campaign's with the campaign
(``campaign/``).
"""
