"""Episode lists of the benchmark protocols (paper section 4; SPEC section 8).

Seeds are disjoint by construction: training demos use ``TRAIN_SEED_BASE + 100_000 * task + i``,
ID evaluation states ``ID_SEED_BASE + 1_000 * task + i`` (i < 50); OOD episodes reuse the ID
task, seed and therefore initial state, with one physical factor changed.
"""

from __future__ import annotations

from ..tasks.suites import NUM_TASKS, OOD_CONDITIONS, SUITES

TRAIN_SEED_BASE = 0
ID_SEED_BASE = 50_000_000
ID_EPISODES_PER_TASK = 50
TRAIN_DEMOS_PER_TASK = 100


def train_seed(task_id: int, i: int) -> int:
    if not 0 <= i < 100_000:
        raise ValueError(f"demo index must be in [0, 100000), got {i}")
    return TRAIN_SEED_BASE + 100_000 * task_id + i


def id_seed(task_id: int, i: int) -> int:
    if not 0 <= i < 1_000:
        raise ValueError(f"evaluation index must be in [0, 1000), got {i}")
    return ID_SEED_BASE + 1_000 * task_id + i


def episodes(suite: str, protocol: str = "id", tasks=None, per_task: int = ID_EPISODES_PER_TASK,
             conditions=None) -> list[dict]:
    """The (suite, task_id, condition, seed) list of a protocol, in a fixed order."""
    if suite not in SUITES:
        raise ValueError(f"unknown suite '{suite}'; choose one of {sorted(SUITES)}")
    tasks = list(range(NUM_TASKS)) if tasks is None else list(tasks)
    if protocol == "id":
        conds = ["id"]
    elif protocol == "ood":
        if SUITES[suite][2] != "soft":
            raise ValueError(f"the OOD protocol applies to the deformable suites, not '{suite}'")
        conds = list(conditions or OOD_CONDITIONS)
        unknown = [c for c in conds if c not in OOD_CONDITIONS]
        if unknown:
            raise ValueError(f"unknown OOD conditions {unknown}; choose from {sorted(OOD_CONDITIONS)}")
    else:
        raise ValueError(f"protocol must be 'id' or 'ood', got '{protocol}'")
    return [{"suite": suite, "task_id": t, "condition": c, "seed": id_seed(t, i)}
            for c in conds for t in tasks for i in range(per_task)]


def episode_key(ep: dict) -> tuple:
    return (ep["suite"], int(ep["task_id"]), ep["condition"], int(ep["seed"]))
