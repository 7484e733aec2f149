"""The command lives in :mod:`mani_skill_softvt.cli.demos`, its library in
:mod:`mani_skill_softvt.demonstrations` (generate, render, stats). This path is the one README and the
benchmark's users type, ``python -m mani_skill_softvt.demos``: it stays, as a thin alias of the
command (``softvt-demos`` is the same); its old library names are re-exported for one release."""

from .cli.demos import main  # noqa: F401
from .demonstrations.generate import (accepted_demos_expected, generate, merged_is_current,  # noqa: F401
                                      record_demo)
from .demonstrations.render import CURRENT_RENDER_KEYS, render, render_observations, rendering_is_current  # noqa: F401
from .demonstrations.stats import format_stats, rerecord_agreement, stats  # noqa: F401

if __name__ == "__main__":
    main()
