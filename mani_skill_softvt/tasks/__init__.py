"""SoftVT task environments (importing this registers them with ManiSkill/Gymnasium)."""

from . import grasp_lift  # noqa: F401
from .soft_body_env import SoftBodyEnv, SoftObjectSpec  # noqa: F401
