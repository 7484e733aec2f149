"""Episode costs of the SoftVT suites beside ManiSkill's PickCube-v1, measured in the same run.

    .venv/bin/python benchmarks/bench_episodes.py [--skip-rigid]

Rows (CPU, one process, 240 Hz physics, 20 Hz control):

- wall seconds per simulated second of one scripted-expert episode (object_soft and object_rigid
  task 3, obs_mode state_dict), with soft-body sleeping and without (``soft_sleep=False``),
  against PickCube-v1 physics only (obs_mode state, random actions);
- milliseconds per idle ``rgb+tactile`` control step per camera (the robot holding still away
  from the object, which sleeps) against PickCube-v1 with one 224x224 camera;
- the same per-step cost of a 100-step ``hold`` episode with and without sleeping.

The ratio column divides by the PickCube row measured in this run, so machines compare.
"""

from __future__ import annotations

import argparse
import time

from bench_sim_speed import bench_pickcube  # same directory: the one PickCube baseline

CAMERAS = 2  # base_camera + hand_camera of the SoftVT tasks


def pickcube(obs_mode: str, steps: int) -> float:
    """Wall seconds per control step of PickCube-v1 (random actions, 224x224 camera)."""
    return 1.0 / (20.0 * bench_pickcube(obs_mode, steps))  # bench_pickcube: simulated s per wall s


def expert_episode(suite: str, sleep: bool) -> tuple[float, dict]:
    """Wall seconds per simulated second of one expert episode; the record and the tick counts."""
    from mani_skill_softvt.data.seeds import id_seed
    from mani_skill_softvt.evaluation.policies import ScriptedExpertPolicy
    from mani_skill_softvt.evaluation.runner import run_episode
    from mani_skill_softvt.evaluation.wrapper import make_env

    env = make_env(suite, 3, obs_mode="state_dict", control_mode="pd_ee_pose", soft_sleep=sleep)
    rec = run_episode(env, ScriptedExpertPolicy(), {"suite": suite, "task_id": 3, "condition": "id",
                                                    "seed": id_seed(3, 0)})
    stats = env.unwrapped.soft_world_stats
    env.close()
    return rec["wall_s"] / (rec["steps"] / 20.0), {**stats, "termination": rec["termination"], "r_max": rec["r_max"]}


def hold_steps(sleep: bool, steps: int, skip: int) -> float:
    """Wall seconds per rgb+tactile control step of the hold policy, after ``skip`` warm-up steps."""
    from mani_skill_softvt.evaluation.policies import HoldPolicy
    from mani_skill_softvt.evaluation.wrapper import make_env

    env = make_env("object_soft", 3, obs_mode="rgb+tactile", control_mode="pd_ee_pose", soft_sleep=sleep)
    obs, _ = env.reset(seed=0)
    policy = HoldPolicy()
    policy.reset("", 0)
    action = policy.act(obs)[0]
    for _ in range(skip):
        env.step(action)
    t0 = time.perf_counter()
    for _ in range(steps):
        env.step(action)
    wall = time.perf_counter() - t0
    env.close()
    return wall / steps


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--skip-rigid", action="store_true", help="leave out the rigid-twin expert episode")
    args = ap.parse_args(argv)
    from tqdm import tqdm

    jobs = [("pick_state", lambda: pickcube("state", 100)), ("pick_rgb", lambda: pickcube("rgb", 40)),
            ("soft_sleep", lambda: expert_episode("object_soft", True)),
            ("soft_awake", lambda: expert_episode("object_soft", False)),
            ("idle_sleep", lambda: hold_steps(True, 40, 20)), ("idle_awake", lambda: hold_steps(False, 40, 20))]
    if not args.skip_rigid:
        jobs.append(("rigid_sleep", lambda: expert_episode("object_rigid", True)))
    r = {}
    for name, job in tqdm(jobs, desc="benchmark", unit="row"):
        r[name] = job()
    pick_phys = r["pick_state"] * 20.0  # wall s per simulated s
    pick_cam = r["pick_rgb"] * 1e3  # ms per step, one camera
    print(f"\nPickCube-v1 (same run): {pick_phys:.3f} wall s per simulated s (physics only), "
          f"{pick_cam:.1f} ms per step with one 224x224 camera\n")
    print(f"{'row':<58}{'value':>12}{'ratio to PickCube':>20}")
    for key, label in (("soft_sleep", "soft expert episode, sleeping (wall s / sim s)"),
                       ("soft_awake", "soft expert episode, never sleeping (wall s / sim s)"),
                       ("rigid_sleep", "rigid-twin expert episode, sleeping (wall s / sim s)")):
        if key in r:
            v, stats = r[key]
            print(f"{label:<58}{v:>12.3f}{v / pick_phys:>20.1f}   "
                  f"[{stats['termination']}, R_max {stats['r_max']:.4f}, ticks asleep {stats['ticks_asleep']}"
                  f" of {stats['ticks_asleep'] + stats['ticks_simulated']}]")
    for key, label in (("idle_sleep", "idle rgb+tactile step per camera, sleeping (ms)"),
                       ("idle_awake", "idle rgb+tactile step per camera, never sleeping (ms)")):
        v = r[key] * 1e3 / CAMERAS
        print(f"{label:<58}{v:>12.1f}{v / pick_cam:>20.2f}")


if __name__ == "__main__":
    main()
