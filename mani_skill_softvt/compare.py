"""Moved to :mod:`mani_skill_softvt.cli.compare` (the commands' shelf). This path is an alias for one
release, so that ``python -m mani_skill_softvt.compare`` and imports from it keep working."""

from .cli.compare import *  # noqa: F401,F403
from .cli.compare import main  # noqa: F401

if __name__ == "__main__":
    from .cli import moved_command

    moved_command("mani_skill_softvt.compare", "mani_skill_softvt.cli.compare", "softvt-compare")
    main()
