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

import sys


def moved_command(old: str, new: str, console: str | None = None) -> None:
    """The note an old ``python -m`` path prints before it runs its command from the new place (one
    release, then the old path goes)."""
    also = f" (or {console})" if console else ""
    print(f"note: python -m {old} moved to python -m {new}{also}; the old path goes with the next release",
          file=sys.stderr)
