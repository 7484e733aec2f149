"""Moved to :mod:`mani_skill_softvt.provenance.numerics` (provenance, beside every version marker and the seal). This path is an alias for one
release: it is that module itself (one module object, whichever path imports it first), so code and
pickles that name ``mani_skill_softvt.numerics`` keep working."""

import sys

from .provenance import numerics as _moved

if __name__ != "__main__":  # imported: be the moved module (run with -m, there is nothing to run)
    sys.modules[__name__] = _moved
