"""Moved to :mod:`mani_skill_softvt.integrations.maniskill.replay` (console name ``softvt-replay``). This path is an alias for
one release, so that ``python -m mani_skill_softvt.replay`` and imports from it keep working."""

from .integrations.maniskill.replay import *  # noqa: F401,F403
from .integrations.maniskill.replay import cli, main  # noqa: F401

if __name__ == "__main__":
    from .cli import moved_command

    moved_command("mani_skill_softvt.replay", "mani_skill_softvt.integrations.maniskill.replay", "softvt-replay")
    cli()
