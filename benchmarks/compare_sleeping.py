"""Does soft-body sleeping change the score? The expert on every Object-Soft task, ID seed 0,
with sleeping and without (docs/physics.md; the issue's bound: same success, R_max
within 1e-3).

    .venv/bin/python benchmarks/compare_sleeping.py [--tasks 0 1 ... 9] [--json out.json]

About 10 min on one core for the ten tasks. Prints a table: per task, success both ways, R_max
both ways, their gap, and the ticks the object slept.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from mani_skill_softvt.fileio import atomic_write_json

R_MAX_BOUND = 1e-3  # the simulation-cost issue's bound


def episode(task_id: int, sleep: bool) -> dict:
    from mani_skill_softvt.data.seeds import id_seed
    from mani_skill_softvt.evaluation.policies import ScriptedExpertPolicy
    from mani_skill_softvt.evaluation.runner import run_episode
    from mani_skill_softvt.evaluation.wrapper import make_env

    env = make_env("object_soft", task_id, obs_mode="state_dict", control_mode="pd_ee_pose", soft_sleep=sleep)
    try:
        rec = run_episode(env, ScriptedExpertPolicy(),
                          {"suite": "object_soft", "task_id": task_id, "condition": "id", "seed": id_seed(task_id, 0)})
        asleep = int(env.unwrapped.soft_world_stats["ticks_asleep"])
    finally:
        env.close()
    return {"termination": rec["termination"], "r_max": rec["r_max"], "ticks_asleep": asleep}


def main() -> None:
    from mani_skill_softvt.tasks.suites import NUM_TASKS

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tasks", type=int, nargs="+", default=list(range(NUM_TASKS)))
    ap.add_argument("--json", type=Path, help="also write the rows to this file")
    args = ap.parse_args()
    rows = []
    for t in tqdm(args.tasks, desc="tasks", unit="task"):
        on, off = episode(t, True), episode(t, False)
        rows.append({"task_id": t, "sleeping": on, "never_sleeping": off, "r_max_gap": abs(on["r_max"] - off["r_max"])})
    print("| task | sleeping | never sleeping | R_max sleeping | R_max never | gap | within 1e-3 | ticks asleep |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        on, off = r["sleeping"], r["never_sleeping"]
        print(f"| {r['task_id']} | {on['termination']} | {off['termination']} | {on['r_max']:.5f} | {off['r_max']:.5f} "
              f"| {r['r_max_gap']:.1e} | {r['r_max_gap'] <= R_MAX_BOUND} | {on['ticks_asleep']} |")
    if args.json:
        atomic_write_json(args.json, {"rows": rows})


if __name__ == "__main__":
    main()
