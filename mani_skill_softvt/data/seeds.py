"""The seed ranges of the benchmark: training demos, ID evaluation states, calibration trials.

One integer per episode drives every random choice of that episode (layout, robot initialisation,
the expert's closure). The ranges are disjoint by construction, so no evaluation state was ever
seen in training and no calibration trial reuses either:

- training demos: ``TRAIN_SEED_BASE + 100_000 * task + i`` (i < 100_000);
- ID evaluation states: ``ID_SEED_BASE + 1_000 * task + i`` (i < 1_000; the protocol uses 50);
  OOD episodes reuse the ID seeds (same initial state, one physical factor changed);
- calibration trials: ``CALIBRATION_SEED_BASE + 1_000_000 * asset + 10 * round(1000 * closure) + repeat``.
"""

from __future__ import annotations

TRAIN_SEED_BASE = 0
ID_SEED_BASE = 50_000_000
CALIBRATION_SEED_BASE = 10_000
ID_EPISODES_PER_TASK = 50  # the paper's ID protocol: 50 held-out initial states per task


def train_seed(task_id: int, i: int) -> int:
    """Seed of the ``i``-th training demo of a task."""
    if not 0 <= i < 100_000:
        raise ValueError(f"demo index must be in [0, 100000), got {i}")
    return TRAIN_SEED_BASE + 100_000 * task_id + i


def id_seed(task_id: int, i: int) -> int:
    """Seed of the ``i``-th ID evaluation state of a task (OOD episodes reuse it)."""
    if not 0 <= i < 1_000:
        raise ValueError(f"evaluation index must be in [0, 1000), got {i}")
    return ID_SEED_BASE + 1_000 * task_id + i


def calibration_seed(asset_index: int, closure: float, repeat: int) -> int:
    """One seed per calibration trial (asset, closure, repeat): placement, yaw and jitter.

    Keyed by the closure's value, so a quick run at a few closures repeats the full sweep's
    trials at those closures exactly.
    """
    if not 0 <= repeat < 10:
        raise ValueError(f"repeat must be in [0, 10), got {repeat}")
    return CALIBRATION_SEED_BASE + 1_000_000 * asset_index + 10 * int(round(closure * 1000)) + repeat
