"""The command lives in :mod:`mani_skill_softvt.cli.calibrate`, its trials and sweeps in
:mod:`mani_skill_softvt.expert.calibration_trials`. This path is the one README and the benchmark's
users type, ``python -m mani_skill_softvt.calibrate``: it stays, as a thin alias of the command
(``softvt-calibrate`` is the same); its old library names are re-exported for one release."""

from .cli.calibrate import QUICK_ASSET, QUICK_CLOSURES, main  # noqa: F401
from .expert.calibration_trials import *  # noqa: F401,F403

if __name__ == "__main__":
    main()
