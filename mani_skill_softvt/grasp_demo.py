"""Moved to :mod:`mani_skill_softvt.cli.grasp_demo` (the commands' shelf). This path is an alias for one
release, so that ``python -m mani_skill_softvt.grasp_demo`` and imports from it keep working."""

from .cli.grasp_demo import *  # noqa: F401,F403
from .cli.grasp_demo import main  # noqa: F401

if __name__ == "__main__":
    from .cli import moved_command

    moved_command("mani_skill_softvt.grasp_demo", "mani_skill_softvt.cli.grasp_demo", None)
    main()
