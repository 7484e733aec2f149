"""Simulation speed of the coupled soft-body scene vs ManiSkill's own PickCube-v1, same run.

    .venv/bin/python benchmarks/bench_sim_speed.py [--steps 60]

Both envs run on the CPU at the lockstep rate (240 Hz physics, 20 Hz control). Rows:
physics only (obs_mode="state"), with one 224x224 camera rendered every control step
(obs_mode="rgb"), and physics only on the cube's rigid twin (a PhysX rigid body: no Newton world).
Prints simulated seconds per wall second and the ratio to PickCube-v1.
The soft-body scene runs the scripted grasp (approach, descend, close, lift, hold), so the
FEM body is in contact with the table and the pads for most of the measurement.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np


def _time_steps(env, actions) -> float:
    t0 = time.perf_counter()
    for a in actions:
        env.step(a)
    return time.perf_counter() - t0


def bench_softvt(obs_mode: str, steps: int, asset_id: str) -> float:
    import mani_skill_softvt.tasks  # noqa: F401
    from mani_skill_softvt.expert.grasp_script import GraspPlan
    from mani_skill_softvt.contracts.actions import ee_action
    from mani_skill_softvt.tasks.robot import mid_height_grasp

    env = gym.make("SoftGraspLift-v1", obs_mode=obs_mode, control_mode="pd_ee_pose", asset_id=asset_id,
                   sensor_configs=dict(width=224, height=224))
    env.reset(seed=0)
    u = env.unwrapped
    plan = GraspPlan()
    nodes = u.soft_nodes()
    xy = nodes.mean(axis=0)[:2]
    actions, tcp = [], u.agent.tcp.pose.p[0].numpy().astype(np.float64)
    for phase, target, g in plan.phases(xy, mid_height_grasp(nodes))[:5]:
        n = plan.steps[phase]
        for i in range(n):
            actions.append(ee_action(tcp + (target - tcp) * min(1.0, (i + 1) / max(1, n - 2)), g))
        tcp = target
    env.step(actions[0])  # first render / first graph launch outside the timing
    actions = actions[1 : steps + 1]
    wall = _time_steps(env, actions)
    env.close()
    return len(actions) / 20.0 / wall


def bench_pickcube(obs_mode: str, steps: int) -> float:
    import mani_skill.envs  # noqa: F401

    env = gym.make("PickCube-v1", obs_mode=obs_mode, sim_backend="physx_cpu", render_backend="cpu",
                   control_mode="pd_ee_delta_pose", sim_config=dict(sim_freq=240, control_freq=20),
                   sensor_configs=dict(width=224, height=224))
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-0.2, 0.2, size=env.action_space.shape).astype(np.float32) for _ in range(steps + 1)]
    env.step(actions[0])
    wall = _time_steps(env, actions[1:])
    env.close()
    return steps / 20.0 / wall


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=60, help="control steps measured per row (max 104)")
    args = ap.parse_args(argv)
    from mani_skill_softvt.assets import load_card
    from mani_skill_softvt.tasks.grasp_lift import DEFAULT_ASSET

    twin = load_card(DEFAULT_ASSET).twin_id
    rows, base = [], {}
    for mode, label, asset in (("state", "physics only", DEFAULT_ASSET),
                               ("rgb", "one 224x224 camera", DEFAULT_ASSET),
                               ("state", "physics only, rigid twin (PhysX)", twin)):
        soft = bench_softvt(mode, args.steps, asset)
        if mode not in base:
            base[mode] = bench_pickcube(mode, args.steps)
        rows.append((label, soft, base[mode]))
    print(f"\n{'scene (240 Hz physics, 20 Hz control, CPU)':<44}{'SoftGraspLift-v1':>18}{'PickCube-v1':>15}{'ratio':>8}")
    print(f"{'':<44}{'sim s / wall s':>18}{'sim s / wall s':>15}{'':>8}")
    for label, soft, base in rows:
        print(f"{label:<44}{soft:>18.3f}{base:>15.3f}{soft / base:>8.3f}")


if __name__ == "__main__":
    main()
