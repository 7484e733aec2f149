"""Moved to :mod:`mani_skill_softvt.contracts.observations` (the contracts' shelf). This path is an alias for one
release: it is that module itself (one module object, whichever path imports it first), so code and
pickles that name ``mani_skill_softvt.observations`` keep working."""

import sys

from .contracts import observations as _moved

if __name__ != "__main__":  # imported: be the moved module (run with -m, there is nothing to run)
    sys.modules[__name__] = _moved
