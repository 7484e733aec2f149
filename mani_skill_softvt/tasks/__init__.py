"""SoftVT task environments (importing this registers them with ManiSkill/Gymnasium)."""

from . import grasp_lift, softvt_task  # noqa: F401
from .soft_body_env import SoftBodyEnv, ObjectSpec  # noqa: F401
from .softvt_task import SoftVTTaskEnv  # noqa: F401
from .suites import OOD_CONDITIONS, SUITES, list_tasks, task_spec  # noqa: F401
