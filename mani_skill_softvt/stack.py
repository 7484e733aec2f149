"""Moved to :mod:`mani_skill_softvt.provenance.stack` (provenance, beside every version marker and the seal). This path is an alias for one
release: it is that module itself (one module object, whichever path imports it first), so code and
pickles that name ``mani_skill_softvt.stack`` keep working; ``python -m mani_skill_softvt.stack`` runs its command."""

import sys

from .provenance import stack as _moved

if __name__ == "__main__":
    from .cli import moved_command

    moved_command("mani_skill_softvt.stack", "mani_skill_softvt.provenance.stack")
    _moved.main()
else:
    sys.modules[__name__] = _moved
