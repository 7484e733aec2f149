"""Moved to :mod:`mani_skill_softvt.integrations.maniskill.diffusion_policy`. This path is an alias for
one release, so that ``--policy mani_skill_softvt.evaluation.maniskill_dp:ManiSkillDiffusionPolicy``
keeps working (the layering test lists it among the aliases)."""

from ..integrations.maniskill.diffusion_policy import *  # noqa: F401,F403
from ..integrations.maniskill.diffusion_policy import ManiSkillDiffusionPolicy, flatten_observation  # noqa: F401
