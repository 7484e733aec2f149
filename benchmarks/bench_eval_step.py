"""What an evaluation step of a learned policy costs, broken down, beside PickCube-v1 in the same run.

    .venv/bin/python benchmarks/bench_eval_step.py [--camera 84] [--calls 10]

The scripted expert's actions of one Object-Soft episode (task 3, the first ID seed) are recorded
once, then replayed step by step in three obs modes (``--repeats`` times each, the fastest kept),
with the cameras at ``--camera`` px: ``state_dict`` (physics: PhysX, the FEM and their coupling,
plus the state), ``rgb`` (+ the two cameras) and ``rgb+tactile`` (+ both GelSights). The
differences are the cameras' and the touch's share; the same actions give the same physics in every
mode. ``rgb+tactile`` at 224 px shows what rendering at the policy's size cut. A Diffusion Policy
step (``cpu`` preset, one thread) adds its inputs (resizing, ``features.frame_features``) every
step and one denoised chunk every ``action_steps`` steps, timed on the replay's last observation
with untrained weights (the cost does not depend on them).

The evaluator renders the cameras only for the observations a policy reads (``Policy.needs_next_images``):
the cpu agent reads the last ``obs_horizon`` frames before each replanning, 2 of every 8 steps.
``rgb+tactile, cameras where read`` replays with that pattern; its difference from ``rgb+tactile``
is what the skipping saves.

``x PickCube`` divides by a PickCube-v1 control step (physics and one camera at the same size,
random actions) measured in this run, so machines compare.

An episode also begins with a reset. Every reset rebuilds the scene (``reconfiguration_freq=1``,
the default), which makes an episode independent of what ran before it in the env; the reset is
timed in ``rgb+tactile`` with the rebuild, with a plain reset (``reconfiguration_freq=0``) and
beside a PickCube-v1 reset that rebuilds its scene too.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def expert_actions(task: int, seed: int) -> list[np.ndarray]:
    from mani_skill_softvt.evaluation.policies import ScriptedExpertPolicy
    from mani_skill_softvt.evaluation.wrapper import make_env
    from mani_skill_softvt.rollout import Observer, rollout

    actions = []

    class Keep(Observer):
        def on_step(self, env, action, obs, info):
            actions.append(np.asarray(action).copy())

    env = make_env("object_soft", task, obs_mode="state_dict")
    rollout(env, ScriptedExpertPolicy(), seed, observers=[Keep()])
    env.close()
    return actions


def read_by_agent(step: int, obs_horizon: int, action_steps: int) -> bool:
    """Whether the cpu agent reads step ``step``'s frame: it replans at multiples of
    ``action_steps`` from the last ``obs_horizon`` frames (baselines/agent.py)."""
    return (-step) % action_steps < obs_horizon


def replay(task: int, seed: int, actions, obs_mode: str, camera: int, read=None) -> tuple[float, object]:
    """Milliseconds per step of replaying ``actions`` in ``obs_mode``; the last observation.
    ``read(step)``: False skips the cameras of that step (1-based), as the evaluator does."""
    from mani_skill_softvt.evaluation.wrapper import make_env

    env = make_env("object_soft", task, obs_mode=obs_mode, camera_size=(camera, camera))
    obs, _ = env.reset(seed=seed)
    obs = env.step(actions[0])[0]  # outside the timing: the renderer's first frame builds its pipelines
    t0 = time.perf_counter()
    for step, a in enumerate(actions[1:], 2):
        if read is not None and not read(step):
            env.unwrapped.skip_cameras_next_step()
        obs = env.step(a)[0]
    ms = 1e3 * (time.perf_counter() - t0) / (len(actions) - 1)
    env.close()
    return ms, obs


def ms_per_reset(env, first_seed: int, resets: int) -> float:
    """Milliseconds per ``env.reset`` over ``resets`` seeds from ``first_seed``."""
    t0 = time.perf_counter()
    for i in range(resets):
        env.reset(seed=first_seed + i)
    return 1e3 * (time.perf_counter() - t0) / resets


def reset_ms(task: int, seed: int, camera: int, rebuild: bool, resets: int) -> float:
    """Milliseconds per ``env.reset(seed=...)`` in rgb+tactile, the scene rebuilt or not; the
    first reset (the env's construction) outside the timing."""
    from mani_skill_softvt.evaluation.wrapper import make_env

    env = make_env("object_soft", task, obs_mode="rgb+tactile", camera_size=(camera, camera),
                   reconfiguration_freq=1 if rebuild else 0)
    env.reset(seed=seed)
    ms = ms_per_reset(env, seed + 1, resets)
    env.close()
    return ms


def pickcube_reset_ms(camera: int, resets: int) -> float:
    """Milliseconds per PickCube-v1 reset that rebuilds its scene, as ours do."""
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401

    env = gym.make("PickCube-v1", obs_mode="rgb", reconfiguration_freq=1, sensor_configs={"width": camera, "height": camera})
    env.reset(seed=0)
    ms = ms_per_reset(env, 1, resets)
    env.close()
    return ms


def pickcube_step(camera: int, steps: int = 40) -> float:
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401

    env = gym.make("PickCube-v1", obs_mode="rgb", control_mode="pd_ee_delta_pose",
                   sim_config={"sim_freq": 240, "control_freq": 20}, sensor_configs={"width": camera, "height": camera})
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-0.2, 0.2, size=env.action_space.shape).astype(np.float32) for _ in range(steps + 1)]
    env.step(actions[0])
    t0 = time.perf_counter()
    for a in actions[1:]:
        env.step(a)
    ms = 1e3 * (time.perf_counter() - t0) / steps
    env.close()
    return ms


def policy_costs(variant: str, obs, calls: int) -> tuple[float, float, int]:
    """(ms per step of the inputs, ms per denoised chunk, action_steps) of the cpu preset's policy."""
    import torch

    from softvt_campaign.baselines.config import make_config
    from softvt_campaign.baselines.features import frame_features
    from softvt_campaign.baselines.model import DiffusionPolicyModel, noise_scheduler
    from softvt_campaign.baselines.train import empty_stats
    from mani_skill_softvt.contracts.observations import flatten_batch

    torch.set_num_threads(1)
    cfg = make_config(variant)
    t0 = time.perf_counter()
    for _ in range(calls):
        frame = frame_features(flatten_batch(obs), cfg)
    inputs_ms = 1e3 * (time.perf_counter() - t0) / calls
    model = DiffusionPolicyModel(cfg, empty_stats(cfg)).eval()
    window = {k: torch.from_numpy(np.stack([v] * cfg.obs_horizon))[None] for k, v in frame.items()}
    scheduler = noise_scheduler(cfg, inference=True)
    generator = torch.Generator().manual_seed(0)
    model.sample(window, generator, scheduler)  # first call outside the timing
    t0 = time.perf_counter()
    for _ in range(calls):
        model.sample(window, generator, scheduler)
    return inputs_ms, 1e3 * (time.perf_counter() - t0) / calls, cfg.action_steps


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--camera", type=int, default=84, help="camera size (px, square) of the policy")
    ap.add_argument("--calls", type=int, default=10, help="policy calls timed")
    ap.add_argument("--task", type=int, default=3)
    ap.add_argument("--resets", type=int, default=5, help="resets timed in each way")
    ap.add_argument("--repeats", type=int, default=3,
                    help="replays of each obs mode, the fastest kept: the components are differences of "
                         "replays, and one replay's noise (a few ms) is larger than the GelSights' share")
    args = ap.parse_args(argv)
    if min(args.repeats, args.calls, args.resets) < 1:
        ap.error("--repeats, --calls and --resets must be >= 1")
    from tqdm import tqdm

    from mani_skill_softvt.data.seeds import id_seed

    seed = id_seed(args.task, 0)
    from softvt_campaign.baselines.config import make_config

    cfg = make_config("vt-c")
    with tqdm(total=9, desc="benchmark", unit="row") as bar:
        actions = expert_actions(args.task, seed)
        bar.update()
        ms = {}
        for mode, cam in (("state_dict", args.camera), ("rgb", args.camera), ("rgb+tactile", args.camera),
                          ("rgb+tactile", 224)):
            ms[(mode, cam)], obs = min((replay(args.task, seed, actions, mode, cam) for _ in range(args.repeats)),
                                       key=lambda r: r[0])
            if (mode, cam) == ("rgb+tactile", args.camera):
                last = obs
            bar.update()
        skipping = min(replay(args.task, seed, actions, "rgb+tactile", args.camera,
                              read=lambda s: read_by_agent(s, cfg.obs_horizon, cfg.action_steps))[0]
                       for _ in range(args.repeats))
        bar.update()
        vo = policy_costs("vo-c", last, args.calls)
        vt = policy_costs("vt-c", last, args.calls)
        bar.update()
        pick = min(pickcube_step(args.camera) for _ in range(args.repeats))  # the baseline measured as our rows
        bar.update()
        resets = {"rebuilt": reset_ms(args.task, seed, args.camera, True, args.resets),
                  "plain": reset_ms(args.task, seed, args.camera, False, args.resets),
                  "pickcube": pickcube_reset_ms(args.camera, args.resets)}
        bar.update()
    physics = ms[("state_dict", args.camera)]
    cameras = ms[("rgb", args.camera)] - physics
    tactile = ms[("rgb+tactile", args.camera)] - ms[("rgb", args.camera)]
    rows = [("physics (PhysX + FEM + coupling), state", physics),
            (f"two cameras at {args.camera} px", cameras),
            ("two GelSights (tactile images, depth, markers)", tactile)]
    for name, (inputs, chunk, k) in (("vo-c", vo), ("vt-c", vt)):
        rows.append((f"{name} inputs (every step read)", inputs))
        rows.append((f"{name} denoising, {chunk:.0f} ms per chunk / {k} steps", chunk / k))
    total_vt = physics + cameras + tactile + vt[0] + vt[1] / vt[2]
    print(f"\nObject-Soft task {args.task}, {len(actions)} expert steps replayed; PickCube-v1 step "
          f"(one {args.camera}-px camera): {pick:.1f} ms\n")
    print(f"{'component':<52}{'ms/step':>9}{'share of vt-c':>15}{'x PickCube':>12}")
    for name, v in rows:
        share = "" if name.startswith("vo-c") else f"{v / total_vt:>14.0%}"
        print(f"{name:<52}{v:>9.1f}{share:>15}{v / pick:>12.2f}")
    print(f"{'vt-c evaluation step, all of it':<52}{total_vt:>9.1f}{'100%':>15}{total_vt / pick:>12.2f}")
    read_share = np.mean([read_by_agent(s, cfg.obs_horizon, cfg.action_steps) for s in range(1, 1 + len(actions))])
    # Skipping saves the cameras of the unread steps, and the agent computes no inputs for them.
    skipped = total_vt - ms[("rgb+tactile", args.camera)] + skipping - (1 - read_share) * vt[0]
    print(f"{f'vt-c step, cameras only where read ({read_share:.0%} of steps)':<52}{skipped:>9.1f}"
          f"{skipped / total_vt:>15.0%}{skipped / pick:>12.2f}")
    full = ms[("rgb+tactile", 224)]
    print(f"\nrgb+tactile step with 224-px cameras: {full:.1f} ms, at {args.camera} px: "
          f"{ms[('rgb+tactile', args.camera)]:.1f} ms (cut {1 - ms[('rgb+tactile', args.camera)] / full:.0%})")
    print(f"\nreset (rgb+tactile, {args.camera} px), the scene rebuilt: {resets['rebuilt']:.0f} ms; plain: "
          f"{resets['plain']:.0f} ms; PickCube-v1's, rebuilt: {resets['pickcube']:.0f} ms "
          f"(x PickCube {resets['rebuilt'] / resets['pickcube']:.1f})")
    for what, step in (("every camera rendered", total_vt), ("cameras only where read", skipped)):
        episode = 300 * step / 1e3 + resets["rebuilt"] / 1e3
        print(f"a 300-step vt-c episode with its reset, {what}: {episode:.0f} s; the Object-Soft ID protocol "
              f"(500 episodes, at most): {500 * episode / 3.6e3:.1f} core-hours")
    return {"ms": {f"{m}@{c}": v for (m, c), v in ms.items()}, "skipping_ms": skipping, "pickcube_ms": pick,
            "vo": vo, "vt": vt, "reset_ms": resets}


if __name__ == "__main__":
    main()
