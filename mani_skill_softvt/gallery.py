"""Moved to :mod:`mani_skill_softvt.cli.gallery` (the commands' shelf). This path is an alias for one
release, so that ``python -m mani_skill_softvt.gallery`` and imports from it keep working."""

from .cli.gallery import *  # noqa: F401,F403
from .cli.gallery import main  # noqa: F401

if __name__ == "__main__":
    from .cli import moved_command

    moved_command("mani_skill_softvt.gallery", "mani_skill_softvt.cli.gallery", "softvt-gallery")
    main()
