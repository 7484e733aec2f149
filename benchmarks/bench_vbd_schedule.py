"""What a cheaper VBD schedule would buy, and what it would cost the physics.

    .venv/bin/python benchmarks/bench_vbd_schedule.py [--schedules 4x5 4x3 4x2 2x5 4x5@1e-3] [--asset soft_stw_cube_hq]

The soft expert's wall time is the Newton tick (docs/benchmarks.md): substeps x iterations VBD
sweeps per 240 Hz tick. Fewer sweeps are faster, and they change the physics the calibration
cards, tolerances and demonstrations were made with. For each schedule (substeps x iterations,
optionally @ VBD's friction smoothing velocity in m/s; the first row is the package's) this runs, in
one process and beside ManiSkill's PickCube-v1:

- the calibration trial (grasp, lift 10 cm, hold 2 s) of one asset at the loosest closure its card
  holds (g_min) and at the middle of its envelope, same seeds: held or not, slip in the hand over
  the hold, peak D as a fraction of the card's tau_o, mean pad force; and the trial's wall time per
  simulated second against PickCube-v1's physics;
- the resting drift: the object awake on the table (sleeping off), the robot still and away, for
  2 s after the settle: how fast its centroid creeps sideways (VBD's smoothed friction has no
  stiction; an under-converged sweep leaves a net force).

Nothing is changed in the package: each schedule is an override of the env's physics config
(``gym.make(..., physics={"newton_substeps": 2, ...})``, physics/config.py), as a user would pass it.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bench_sim_speed import bench_pickcube  # same directory: the one PickCube baseline

from mani_skill_softvt.fileio import atomic_write_json


def parse_schedule(text: str) -> tuple[int, int, float | None]:
    """'4x5' or '4x5@1e-4': substeps, iterations, friction smoothing velocity (None: the package's)."""
    sched, _, eps = text.lower().partition("@")
    try:
        substeps, iterations = (int(x) for x in sched.split("x"))
        epsilon = float(eps) if eps else None
    except ValueError:
        raise argparse.ArgumentTypeError(f"schedule '{text}': write SUBSTEPSxITERATIONS[@EPSILON], e.g. 4x5 or 4x5@1e-4") from None
    if substeps < 1 or iterations < 1 or (epsilon is not None and not epsilon > 0):
        raise argparse.ArgumentTypeError(f"schedule '{text}': substeps and iterations must be >= 1, epsilon > 0")
    return substeps, iterations, epsilon


def schedule_overrides(substeps: int, iterations: int, epsilon: float | None) -> dict:
    """The env's physics overrides of a schedule (epsilon None: the package's friction smoothing)."""
    return {"newton_substeps": substeps, "vbd_iterations": iterations,
            **({} if epsilon is None else {"friction_epsilon": epsilon})}


def grasp_trials(asset_id: str, closures: list[float], seed: int, physics: dict) -> list[dict]:
    import gymnasium as gym

    import mani_skill_softvt.tasks  # noqa: F401
    from mani_skill_softvt.calibration import protocol as P
    from mani_skill_softvt.expert.calibration_trials import run_trial

    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=asset_id,
                   physics=physics)
    sim_s = sum(P.STEPS.values()) / 20.0
    out = []
    try:
        env.reset(seed=seed)  # kernels, graph capture and the first settle outside the timing
        for g in closures:
            t0 = time.perf_counter()
            rec = run_trial(env, g, seed)
            wall = time.perf_counter() - t0
            out.append({**rec, "wall_per_sim_s": wall / sim_s})
    finally:
        env.close()
    return out


def resting_drift(asset_id: str, seed: int, physics: dict, seconds: float = 2.0) -> float:
    """Sideways speed (m/s) of the awake object's centroid on the table, robot still and away."""
    import gymnasium as gym

    import mani_skill_softvt.tasks  # noqa: F401
    from mani_skill_softvt.contracts.actions import ee_action

    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=asset_id,
                   soft_sleep=False, physics=physics)
    try:
        env.reset(seed=seed)
        u = env.unwrapped
        tcp = u.agent.tcp.pose.p[0].numpy().astype(np.float64)
        hold = ee_action(tcp, 0.0)
        c0 = u.soft_nodes().mean(axis=0)
        steps = int(round(seconds * 20))
        for _ in range(steps):
            env.step(hold)
        c1 = u.soft_nodes().mean(axis=0)
    finally:
        env.close()
    return float(np.linalg.norm((c1 - c0)[:2]) / (steps / 20.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--schedules", nargs="+", type=parse_schedule,
                    default=[(4, 5, None), (4, 3, None), (4, 2, None), (2, 5, None), (4, 5, 1e-3)],
                    help="SUBSTEPSxITERATIONS[@FRICTION_EPSILON] per 240 Hz tick; the first is the reference "
                         "(default: the package's 4x5, cheaper ones, and 4x5 with the 10x more friction "
                         "smoothing the package used before)")
    ap.add_argument("--asset", default="soft_stw_cube_hq")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--pickcube-steps", type=int, default=200)
    ap.add_argument("--json", help="also write the rows to this file")
    args = ap.parse_args()

    from mani_skill_softvt.calibration.cards import load_calibration_card
    from mani_skill_softvt.physics.config import DEFAULT_PHYSICS

    card = load_calibration_card(args.asset)
    closures = [card.g_min, round(0.5 * (card.g_min + card.g_max), 2)]
    pickcube = 1.0 / bench_pickcube("state", args.pickcube_steps)  # wall s per simulated s
    rows = []
    for substeps, iterations, epsilon in args.schedules:
        physics = schedule_overrides(substeps, iterations, epsilon)
        trials = grasp_trials(args.asset, closures, args.seed, physics)
        drift = resting_drift(args.asset, args.seed, physics)
        name = f"{substeps}x{iterations}" + ("" if epsilon is None else f" @ eps {epsilon:g} m/s")
        rows.append({"schedule": name, "sweeps_per_tick": substeps * iterations,
                     "trials": trials, "drift_mm_s": 1e3 * drift})

    print(f"\n{args.asset} (tau_o {card.tau_o:.4f}); PickCube-v1 physics {pickcube:.3f} wall s per simulated s "
          f"(same run); closures g_min {closures[0]} and mid-envelope {closures[1]}, seed {args.seed}; "
          f"friction smoothing {DEFAULT_PHYSICS.friction_epsilon:g} m/s unless the row says otherwise\n")
    print("| schedule | sweeps / tick | closure | held | slip mm | peak D / tau_o | pad N | wall s / sim s "
          "| x PickCube | resting drift mm/s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        for t in r["trials"]:
            slip = "-" if t["slip_mm"] is None else f"{t['slip_mm']:.2f}"
            print(f"| {r['schedule']} | {r['sweeps_per_tick']} | {t['closure']:.2f} | {t['held']} | {slip} "
                  f"| {t['peak_deformation'] / card.tau_o:.3f} | {t['pad_force_n']:.2f} "
                  f"| {t['wall_per_sim_s']:.2f} | {t['wall_per_sim_s'] / pickcube:.0f}x | {r['drift_mm_s']:.3f} |")
    if args.json:
        atomic_write_json(Path(args.json), {"asset": args.asset, "pickcube_wall_per_sim_s": pickcube, "rows": rows})


if __name__ == "__main__":
    main()
