"""Moved to :mod:`mani_skill_softvt.integrations.openpi.serve` (console name ``softvt-serve``). This path is an alias for
one release, so that ``python -m mani_skill_softvt.serve`` and imports from it keep working."""

from .integrations.openpi.serve import *  # noqa: F401,F403
from .integrations.openpi.serve import main  # noqa: F401

if __name__ == "__main__":
    from .cli import moved_command

    moved_command("mani_skill_softvt.serve", "mani_skill_softvt.integrations.openpi.serve", "softvt-serve")
    main()
