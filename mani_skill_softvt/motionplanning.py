"""Moved to :mod:`mani_skill_softvt.integrations.maniskill.motionplanning` (console name ``softvt-motionplanning``). This path is an alias for
one release, so that ``python -m mani_skill_softvt.motionplanning`` and imports from it keep working."""

from .integrations.maniskill.motionplanning import *  # noqa: F401,F403
from .integrations.maniskill.motionplanning import cli, main  # noqa: F401

if __name__ == "__main__":
    from .cli import moved_command

    moved_command("mani_skill_softvt.motionplanning", "mani_skill_softvt.integrations.maniskill.motionplanning", "softvt-motionplanning")
    cli()
