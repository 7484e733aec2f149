"""The four SoftVTBench suites and their ten tasks each (paper appendix, task table; SPEC section 7).

A suite is (object type) x (variation axis): ``object_*`` suites hold the layout fixed and vary
the object per task; ``spatial_*`` suites place two identical instances and name one by side.
Rigid suites reuse the soft suites' layouts and instructions with the rigid twins.
"""

from __future__ import annotations

from dataclasses import dataclass

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

SUITES = {
    # name: (env id, layout, object kind)
    "object_soft": ("SoftVTObjectSoft-v1", "object", "soft"),
    "spatial_soft": ("SoftVTSpatialSoft-v1", "spatial", "soft"),
    "object_rigid": ("SoftVTObjectRigid-v1", "object", "rigid"),
    "spatial_rigid": ("SoftVTSpatialRigid-v1", "spatial", "rigid"),
}
NUM_TASKS = len(_TASK_TABLE)


@dataclass(frozen=True)
class TaskSpec:
    suite: str
    task_id: int
    asset_id: str  # the object's asset (rigid twin id in rigid suites)
    soft_asset_id: str  # the soft asset it derives from (its calibration card)
    instruction: str
    target: str  # "basket" (object suites) or "plate" (spatial suites)
    side: str | None  # "left"/"right": which of the two instances is instructed (spatial suites)


def twin_id(soft_asset_id: str) -> str:
    if not soft_asset_id.startswith("soft_"):
        raise ValueError(f"'{soft_asset_id}' is not a soft asset id (soft_...)")
    return "rigid_" + soft_asset_id[len("soft_"):]


def task_spec(suite: str, task_id: int) -> TaskSpec:
    if suite not in SUITES:
        raise ValueError(f"unknown suite '{suite}'; choose one of {sorted(SUITES)}")
    if not (isinstance(task_id, int) and 0 <= task_id < NUM_TASKS):
        raise ValueError(f"task_id must be an integer in [0, {NUM_TASKS - 1}], got {task_id!r}")
    soft_id, obj_words, side, spatial_words = _TASK_TABLE[task_id]
    _, layout, kind = SUITES[suite]
    asset = soft_id if kind == "soft" else twin_id(soft_id)
    if layout == "object":
        return TaskSpec(suite, task_id, asset, soft_id, f"Pick up the {obj_words} and place it in the basket.", "basket", None)
    return TaskSpec(suite, task_id, asset, soft_id,
                    f"Pick up the {side} {spatial_words} and place it on the plate.", "plate", side)


def list_tasks(suite: str) -> list[TaskSpec]:
    """All ten tasks of a suite, with their verbatim instructions."""
    return [task_spec(suite, i) for i in range(NUM_TASKS)]
