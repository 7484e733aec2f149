"""Episode costs of the SoftVT suites beside ManiSkill's PickCube-v1, measured in the same run.

    .venv/bin/python benchmarks/bench_episodes.py [--suites object_soft ...] [--workers 2]

Rows (CPU, one process, 240 Hz physics, 20 Hz control):

- wall seconds per simulated second of one scripted-expert episode (task 3 of each suite,
  obs_mode state_dict; Object-Soft also without soft-body sleeping, ``soft_sleep=False``; the
  rigid suites' twins are PhysX rigid bodies),
  against PickCube-v1 physics only (obs_mode state, random actions), and its wall time;
- milliseconds per idle ``rgb+tactile`` control step per camera (the robot holding still away
  from the object, which sleeps) against PickCube-v1 with one 224x224 camera;
- estimates for the 4,000-demo set and the Object-Soft ID protocol (500 episodes), per core
  and on ``--workers`` processes.

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
    """Wall seconds per simulated second of one expert episode; its wall time, outcome and tick counts."""
    from mani_skill_softvt.data.seeds import id_seed
    from mani_skill_softvt.evaluation.policies import ScriptedExpertPolicy
    from mani_skill_softvt.evaluation.runner import run_episode
    from mani_skill_softvt.evaluation.wrapper import make_env

    env = make_env(suite, 3, obs_mode="state_dict", control_mode="pd_ee_pose", soft_sleep=sleep)
    rec = run_episode(env, ScriptedExpertPolicy(), {"suite": suite, "task_id": 3, "condition": "id",
                                                    "seed": id_seed(3, 0)})
    stats = env.unwrapped.soft_world_stats or {}  # None: rigid twins, no Newton world
    env.close()
    return rec["wall_s"] / (rec["steps"] / 20.0), {**stats, "termination": rec["termination"], "r_max": rec["r_max"],
                                                   "wall_s": rec["wall_s"]}


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


SUITES = ("object_soft", "object_rigid", "spatial_soft", "spatial_rigid")
DEMOS_PER_SUITE = 1000  # 100 per task x 10 tasks (paper), 4,000 over the four suites
ID_EPISODES = 500  # 50 per task x 10 tasks
MAX_STEPS = 300


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--suites", nargs="+", default=list(SUITES), choices=SUITES,
                    help="suites whose expert episode is timed (sleeping on)")
    ap.add_argument("--workers", type=int, default=2, help="processes assumed by the 'this machine' estimates")
    args = ap.parse_args(argv)
    from tqdm import tqdm

    jobs = [("pick_state", lambda: pickcube("state", 100)), ("pick_rgb", lambda: pickcube("rgb", 40)),
            ("soft_awake", lambda: expert_episode("object_soft", False)),
            ("idle_sleep", lambda: hold_steps(True, 40, 20)), ("idle_awake", lambda: hold_steps(False, 40, 20))]
    jobs += [(suite, lambda suite=suite: expert_episode(suite, True)) for suite in args.suites]
    r = {}
    for name, job in tqdm(jobs, desc="benchmark", unit="row"):
        r[name] = job()
    pick_phys = r["pick_state"] * 20.0  # wall s per simulated s
    pick_cam = r["pick_rgb"] * 1e3  # ms per step, one camera
    print(f"\nPickCube-v1 (same run): {pick_phys:.3f} wall s per simulated s (physics only), "
          f"{pick_cam:.1f} ms per step with one 224x224 camera\n")
    print(f"{'expert episode, task 3 (wall s per simulated s)':<58}{'value':>8}{'x PickCube':>12}{'s/demo':>9}")
    rows = [(s, f"{s}, sleeping") for s in args.suites]
    if "object_soft" in r:
        rows.insert(1, ("soft_awake", "object_soft, never sleeping"))
    for key, label in rows:
        v, st = r[key]
        ticks = (f"ticks asleep {st['ticks_asleep']} of {st['ticks_asleep'] + st['ticks_simulated']}"
                 if "ticks_asleep" in st else "PhysX rigid bodies, no FEM")
        print(f"{label:<58}{v:>8.2f}{v / pick_phys:>12.1f}{st['wall_s']:>9.1f}   [{st['termination']}, R_max "
              f"{st['r_max']:.3f}, {ticks}]")
    print(f"\n{'idle rgb+tactile control step, per camera (ms)':<58}{'value':>8}{'x PickCube':>12}")
    for key, label in (("idle_sleep", "sleeping"), ("idle_awake", "never sleeping")):
        v = r[key] * 1e3 / CAMERAS
        print(f"{label:<58}{v:>8.1f}{v / pick_cam:>12.2f}")
    # Estimates from the rows above: the expert's episode stands for a demo; a weak policy runs all
    # MAX_STEPS steps, bounded by never touching (FEM asleep) and touching throughout (FEM awake).
    print(f"\n{'estimate (hours)':<58}{'per core':>10}{f'{args.workers} workers':>12}")
    demo_s = sum(r[s][1]["wall_s"] for s in args.suites) * DEMOS_PER_SUITE
    print(f"{f'{len(args.suites) * DEMOS_PER_SUITE} demos ({len(args.suites)} suites x {DEMOS_PER_SUITE})':<58}"
          f"{demo_s / 3600:>10.1f}{demo_s / 3600 / args.workers:>12.1f}")
    for label, per_episode in (("Object-Soft ID protocol, expert", r["object_soft"][1]["wall_s"] if "object_soft" in r else None),
                               ("Object-Soft ID protocol, rgb+tactile policy never touching", MAX_STEPS * r["idle_sleep"]),
                               ("Object-Soft ID protocol, rgb+tactile policy touching throughout",
                                MAX_STEPS * r["idle_awake"])):  # an awake FEM tick costs the same in contact
        if per_episode is not None:
            total = ID_EPISODES * per_episode
            print(f"{label:<58}{total / 3600:>10.1f}{total / 3600 / args.workers:>12.1f}")


if __name__ == "__main__":
    main()
