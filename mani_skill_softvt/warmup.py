"""Moved to :mod:`mani_skill_softvt.cli.warmup` (the commands' shelf). This path is an alias for one
release, so that ``python -m mani_skill_softvt.warmup`` and imports from it keep working."""

from .cli.warmup import *  # noqa: F401,F403
from .cli.warmup import main  # noqa: F401

if __name__ == "__main__":
    from .cli import moved_command

    moved_command("mani_skill_softvt.warmup", "mani_skill_softvt.cli.warmup", "softvt-warmup")
    main()
