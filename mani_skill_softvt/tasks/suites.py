"""The four SoftVTBench suites and their ten tasks each (paper appendix, task table).

A suite is (object type) x (variation axis): ``object_*`` suites hold the layout fixed and vary
the object per task; ``spatial_*`` suites place two identical instances and name one by side.
Rigid suites reuse the soft suites' layouts and instructions with the rigid twins.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..assets.cards import twin_id
from ..tactile.constants import model_version
from .constants import NOMINAL_LIGHT_INTENSITY

# task id -> (soft asset id, object words in the Object suites, side and words in the Spatial suites)
_TASK_TABLE = [
    ("soft_pastry001", "white swirled pastry", "left", "white swirled pastry"),
    ("soft_pastry002", "panda-face pastry", "right", "panda-face pastry"),
    ("soft_pastry003", "small chocolate rectangular pastry", "left", "small chocolate rectangular pastry"),
    ("soft_stw_cube_hq", "soft cream-colored cube", "left", "soft cream-colored cube"),
    ("soft_pastry005", "yellow square layered pastry", "left", "yellow square layered pastry"),
    ("soft_stw_cylinder_hq", "soft tan cylinder", "left", "soft tan cylinder"),
    ("soft_pastry011", "golden pastry", "right", "golden pastry"),
    ("soft_stw_cuboid_hq", "golden knotted pastry", "left", "soft cream-colored rectangular block"),
    ("soft_stw_sphere_hq", "soft red ball", "left", "soft red ball"),
    ("soft_pastry010", "orange pumpkin-shaped pastry", "left", "orange pumpkin-shaped pastry"),
]

@dataclass(frozen=True)
class Suite:
    """One benchmark suite: its env id, its layout and whether its objects are the rigid twins."""

    name: str
    env_id: str
    layout: str  # "object" (one object, basket) or "spatial" (two instances, plate)
    rigid: bool  # rigid twins instead of the deformable assets

    @property
    def target(self) -> str:
        """The prop objects are placed in or on."""
        return "basket" if self.layout == "object" else "plate"

    @property
    def tactile_model(self) -> int:
        """The tactile model version of this suite's frames (tactile.constants.model_version)."""
        return model_version(deformable=not self.rigid)

    def frames_tactile_model(self, obs_mode: str) -> int | None:
        """The tactile model version of this suite's observations in ``obs_mode`` (None without touch)."""
        return self.tactile_model if "tactile" in obs_mode else None

    @property
    def twin(self) -> str:
        """The suite of the same layout with the other objects (Object-Soft <-> Object-Rigid)."""
        return next(s.name for s in SUITES.values() if s.layout == self.layout and s.rigid != self.rigid)

    def task_env_id(self, task_id: int) -> str:
        """The env id that names one task of the suite, e.g. ``SoftVTObjectSoft-Task3-v1``: for tools
        that take an env id and no env kwargs (ManiSkill's baselines' ``--env-id``)."""
        task_spec(self.name, task_id)  # validates task_id
        stem, version = self.env_id.rsplit("-v", 1)
        return f"{stem}-Task{task_id}-v{version}"


SUITES = {s.name: s for s in (
    Suite("object_soft", "SoftVTObjectSoft-v1", "object", rigid=False),
    Suite("spatial_soft", "SoftVTSpatialSoft-v1", "spatial", rigid=False),
    Suite("object_rigid", "SoftVTObjectRigid-v1", "object", rigid=True),
    Suite("spatial_rigid", "SoftVTSpatialRigid-v1", "spatial", rigid=True),
)}
NUM_TASKS = len(_TASK_TABLE)


# gymnasium imports the module named before the colon of an env id: ids recorded as
# "mani_skill_softvt:<id>" make the env in a process that never imported the package.
ENV_ID_MODULE = "mani_skill_softvt"


def recorded_env_id(suite: str, task_id: int) -> str:
    """The env id every file of the package records: the task's own id, module-qualified
    (``mani_skill_softvt:SoftVTObjectSoft-Task3-v1``), so ``gym.make`` of it alone (as ManiSkill's
    replay and baselines do) makes the same task."""
    return f"{ENV_ID_MODULE}:{get_suite(suite).task_env_id(task_id)}"


def parse_env_id(env_id: str) -> tuple[str, int | None]:
    """(suite name, task id or None) of a SoftVT env id: a suite's (``SoftVTObjectSoft-v1``: no
    task) or a task's (``SoftVTObjectSoft-Task3-v1``), either with the ``mani_skill_softvt:`` prefix."""
    bare = env_id.split(":", 1)[1] if env_id.startswith(f"{ENV_ID_MODULE}:") else env_id
    for s in SUITES.values():
        if bare == s.env_id:
            return s.name, None
        for k in range(NUM_TASKS):
            if bare == s.task_env_id(k):
                return s.name, k
    examples = ", ".join(sorted(s.env_id for s in SUITES.values()))
    raise ValueError(f"'{env_id}' is not a SoftVT env id; use a suite's id ({examples}) or a task's, "
                     f"e.g. {SUITES['object_soft'].task_env_id(3)} (optionally prefixed '{ENV_ID_MODULE}:')")


def get_suite(name: str) -> Suite:
    """The suite called ``name``; a ValueError lists the known ones."""
    if name not in SUITES:
        raise ValueError(f"unknown suite '{name}'; choose one of {sorted(SUITES)}")
    return SUITES[name]


@dataclass(frozen=True)
class TaskSpec:
    suite: str
    task_id: int
    asset_id: str  # the object's asset (rigid twin id in rigid suites)
    soft_asset_id: str  # the soft asset it derives from (its calibration card)
    instruction: str
    target: str  # "basket" (object suites) or "plate" (spatial suites)
    side: str | None  # "left"/"right": which of the two instances is instructed (spatial suites)
    rigid: bool  # the object is a rigid twin


def task_spec(suite: str, task_id: int) -> TaskSpec:
    s = get_suite(suite)
    if not (isinstance(task_id, int) and not isinstance(task_id, bool) and 0 <= task_id < NUM_TASKS):
        raise ValueError(f"task_id must be an integer in [0, {NUM_TASKS - 1}], got {task_id!r}")
    soft_id, obj_words, side, spatial_words = _TASK_TABLE[task_id]
    asset = twin_id(soft_id) if s.rigid else soft_id
    if s.layout == "object":
        return TaskSpec(suite, task_id, asset, soft_id, f"Pick up the {obj_words} and place it in the basket.",
                        s.target, None, s.rigid)
    return TaskSpec(suite, task_id, asset, soft_id, f"Pick up the {side} {spatial_words} and place it on the plate.",
                    s.target, side, s.rigid)


def swapped_side(task: TaskSpec) -> TaskSpec:
    """A Spatial task with the instruction naming the other instance ("left" <-> "right"), the scene
    the same: the side-swap condition (not the paper's), which tells whether a policy follows the
    instruction or the object's looks and place. ValueError for an Object task (one instance)."""
    if task.side is None:
        raise ValueError(f"{task.suite} task {task.task_id} has one instance: the side swap applies to the Spatial suites")
    other = {"left": "right", "right": "left"}[task.side]
    return replace(task, side=other, instruction=task.instruction.replace(f"the {task.side} ", f"the {other} ", 1))


def list_tasks(suite: str) -> list[TaskSpec]:
    """All ten tasks of a suite, with their verbatim instructions."""
    return [task_spec(suite, i) for i in range(NUM_TASKS)]


# The nine single-factor OOD conditions of the deformable suites (paper section 4.3):
# name -> (reset option, value). Each reuses the ID task, initial state and seed.
OOD_CONDITIONS = {
    "light_67.5": ("light_intensity", 67.5),
    "light_180": ("light_intensity", 180.0),
    "light_270": ("light_intensity", 270.0),
    "mass_x1.25": ("mass_scale", 1.25),
    "mass_x1.75": ("mass_scale", 1.75),
    "mass_x2.5": ("mass_scale", 2.5),
    "youngs_modulus_x0.5": ("youngs_modulus_scale", 0.5),
    "youngs_modulus_x0.8": ("youngs_modulus_scale", 0.8),
    "youngs_modulus_x2.0": ("youngs_modulus_scale", 2.0),
}


@dataclass(frozen=True)
class PhysicalFactors:
    """The physical factors of an episode that OOD conditions vary; the defaults are nominal."""

    light_intensity: float = NOMINAL_LIGHT_INTENSITY  # the paper's dome-light intensity
    mass_scale: float = 1.0
    youngs_modulus_scale: float = 1.0


FACTOR_OPTIONS = tuple(PhysicalFactors.__dataclass_fields__)  # reset options that set one factor


def resolve_factors(options: dict | None) -> PhysicalFactors:
    """Physical factors of a reset: nominal, an ``ood`` condition by name, or explicit factors.

    >>> resolve_factors({"ood": "mass_x2.5"}).mass_scale
    2.5
    """
    options = options or {}
    factors = {}
    name = options.get("ood")
    if name not in (None, "id"):
        if name not in OOD_CONDITIONS:
            raise ValueError(f"unknown OOD condition '{name}'; choose one of {sorted(OOD_CONDITIONS)} or 'id'")
        key, value = OOD_CONDITIONS[name]
        if key in options and float(options[key]) != value:
            raise ValueError(f"reset options name OOD condition '{name}' but also {key}={options[key]}")
        factors[key] = value
    for key in FACTOR_OPTIONS:
        if key in options:
            value = float(options[key])
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"reset option {key} must be a positive finite number, got {options[key]!r}")
            factors[key] = value
    return PhysicalFactors(**factors)
