"""The command lives in :mod:`mani_skill_softvt.cli.evaluate` (the commands' shelf). This path is the one
README and the benchmark's users type, ``python -m mani_skill_softvt.evaluate``: it stays, as a thin
alias of the command (``softvt-evaluate`` is the same)."""

from .cli.evaluate import *  # noqa: F401,F403
from .cli.evaluate import main  # noqa: F401

if __name__ == "__main__":
    main()
