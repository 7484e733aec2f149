"""Episode lists of the benchmark protocols (paper section 4.3).

ID: fixed held-out initial states per task (seeds from :mod:`mani_skill_softvt.data.seeds`,
disjoint from the training seeds); OOD episodes reuse the ID task, seed and therefore initial
state, with one physical factor changed. Side swap (not the paper's; Spatial suites): the ID
episode with the instruction naming the other instance, success requiring that one. Doubled
placement ranges (not the paper's; the difficulty study): the ID episode's random draws with the
object's and the target's placement ranges twice as wide.
"""

from __future__ import annotations

from ..data.seeds import ID_EPISODES_PER_TASK, id_seed
from ..tasks.suites import NUM_TASKS, OOD_CONDITIONS, get_suite

SIDE_SWAP = "side_swap"  # the condition of the side-swap protocol's episodes
PLACEMENT_X2 = "placement_x2"  # the difficulty study's: the ID episodes with the placement ranges doubled
PROTOCOLS = ("id", "ood", SIDE_SWAP, PLACEMENT_X2)


def protocol_of(condition: str) -> str:
    """The protocol an episode's condition belongs to (a record names its condition)."""
    return condition if condition in ("id", SIDE_SWAP, PLACEMENT_X2) else "ood"


def reset_options(condition: str) -> dict:
    """The env's reset options for an episode of ``condition``: none for ID, ``swap_side`` for the
    side swap, ``placement_scale`` 2 for the doubled ranges, the OOD condition otherwise."""
    if condition == "id":
        return {}
    if condition == SIDE_SWAP:
        return {"swap_side": True}
    if condition == PLACEMENT_X2:
        return {"placement_scale": 2.0}
    return {"ood": condition}


def episodes(suite: str, protocol: str = "id", tasks=None, per_task: int = ID_EPISODES_PER_TASK,
             conditions=None) -> list[dict]:
    """The (suite, task_id, condition, seed) list of a protocol, in a fixed order."""
    rigid = get_suite(suite).rigid
    tasks = list(range(NUM_TASKS)) if tasks is None else list(tasks)
    if protocol == "id":
        conds = ["id"]
    elif protocol == "ood":
        if rigid:
            raise ValueError(f"the OOD protocol applies to the deformable suites, not '{suite}'")
        conds = list(conditions or OOD_CONDITIONS)
        unknown = [c for c in conds if c not in OOD_CONDITIONS]
        if unknown:
            raise ValueError(f"unknown OOD conditions {unknown}; choose from {sorted(OOD_CONDITIONS)}")
    elif protocol == SIDE_SWAP:
        if get_suite(suite).layout != "spatial":
            raise ValueError(f"the side swap applies to the Spatial suites (two instances), not '{suite}'")
        conds = [SIDE_SWAP]
    elif protocol == PLACEMENT_X2:
        if get_suite(suite).layout != "object":
            # Doubled, the Spatial pair's range reaches the plate's rim: not a scene the study checked.
            raise ValueError(f"the doubled placement ranges apply to the Object suites, not '{suite}'")
        conds = [PLACEMENT_X2]
    else:
        raise ValueError(f"protocol must be one of {', '.join(PROTOCOLS)}, got '{protocol}'")
    return [{"suite": suite, "task_id": t, "condition": c, "seed": id_seed(t, i)}
            for c in conds for t in tasks for i in range(per_task)]


def episode_key(ep: dict) -> tuple:
    return (ep["suite"], int(ep["task_id"]), ep["condition"], int(ep["seed"]))


def scene_key(ep: dict) -> tuple:
    """An episode's initial state within its suite, whichever condition: the side swap (and the
    doubled placement) reuse the ID seeds, so their episodes pair with the ID ones on this."""
    return (int(ep["task_id"]), int(ep["seed"]))


def seed_key(ep: dict) -> tuple:
    """An episode's place in its protocol, whichever objects: a soft suite and its rigid twin
    draw the same seeds (:func:`episodes`), so their episodes pair on this."""
    return (int(ep["task_id"]), ep["condition"], int(ep["seed"]))
