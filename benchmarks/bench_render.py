"""Rendering cost at the policy's camera size: 224x224 against 84x84, beside PickCube-v1, same run.

    .venv/bin/python benchmarks/bench_render.py [--frames 20] [--size 84]

Rows (CPU, one process):

- ``obs``: milliseconds per observation (``env.get_obs()``, the robot at rest after a reset) of
  Object-Soft task 3 in obs modes ``rgb`` (two cameras) and ``rgb+tactile`` (plus both GelSights),
  with the cameras at 224x224 and at ``--size`` (ManiSkill's ``sensor_configs``), against
  PickCube-v1's one camera at the same sizes;
- ``demo render``: milliseconds per frame of ``demos render`` (restore the stored state, observe)
  over the committed sample demo (Object-Soft task 3), at both sizes.

``ratio`` divides the obs rows by PickCube-v1's at the same size, per camera, so machines
compare (the demo-render rows, which also restore states and render the GelSights, have none);
``saved`` is what rendering at ``--size`` saves against 224x224 and shrinking.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "demo-data" / "sample" / "object_soft" / "task3.h5"


def time_obs(env, frames: int) -> float:
    """Milliseconds per ``get_obs`` (after one untimed call: first render)."""
    u = env.unwrapped
    u.get_obs()
    t0 = time.perf_counter()
    for _ in range(frames):
        u.get_obs()
    return 1e3 * (time.perf_counter() - t0) / frames


def pickcube_obs(size: int, frames: int, obs_mode: str = "rgb") -> float:
    import mani_skill.envs  # noqa: F401

    # "normal" and "albedo" need ManiSkill's default shader pack (its minimal one renders neither).
    shader = {"shader_pack": "default"} if {"normal", "albedo"} & set(obs_mode.split("+")) else {}
    env = gym.make("PickCube-v1", obs_mode=obs_mode, sensor_configs={"width": size, "height": size, **shader})
    env.reset(seed=0)
    ms = time_obs(env, frames)
    env.close()
    return ms


def softvt_obs(obs_mode: str, size: int, frames: int) -> float:
    from mani_skill_softvt.evaluation.wrapper import make_env

    env = make_env("object_soft", 3, dsr=False, obs_mode=obs_mode, camera_size=(size, size))
    env.reset(seed=0)
    ms = time_obs(env, frames)
    env.close()
    return ms


def demo_render(size: int) -> tuple[float, int]:
    """Milliseconds per frame of rendering the sample demo into rgb+tactile at ``size``; frames."""
    from mani_skill_softvt.demonstrations.render import render_observations

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        render_observations(SAMPLE, Path(tmp) / "r.h5", "object_soft", 3, "rgb+tactile", (size, size))
        wall = time.perf_counter() - t0
    import h5py

    with h5py.File(SAMPLE, "r") as f:
        frames = sum(f[k]["actions"].shape[0] + 1 for k in f)
    return 1e3 * wall / frames, frames


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--size", type=int, default=84, help="the policy's camera size (square)")
    args = ap.parse_args(argv)
    sizes = (224, args.size)
    base = {s: pickcube_obs(s, args.frames) for s in sizes}
    rows = [{"what": "obs PickCube-v1 (1 camera)", "size": s, "ms": base[s], "ratio": 1.0} for s in sizes]
    for mode in ("rgb", "rgb+tactile"):
        for s in sizes:
            ms = softvt_obs(mode, s, args.frames)
            rows.append({"what": f"obs Object-Soft {mode} (2 cameras)", "size": s, "ms": ms, "ratio": ms / 2 / base[s]})
    for s in sizes:
        ms, frames = demo_render(s)
        rows.append({"what": f"demo render rgb+tactile ({frames} frames)", "size": s, "ms": ms, "ratio": None})
    by = {(r["what"], r["size"]): r["ms"] for r in rows}
    print(f"{'':44s} {'camera':>7s} {'ms':>8s} {'ratio':>7s} {'saved':>7s}")
    for r in rows:
        full = by[(r["what"], 224)]
        saved = "" if r["size"] == 224 else f"{1 - r['ms'] / full:6.0%}"
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.2f}"
        print(f"{r['what']:44s} {r['size']:>4d} px {r['ms']:8.1f} {ratio:>7s} {saved:>7s}")
    print("ratio: per camera against PickCube-v1's one camera at the same size (obs rows); saved: against 224x224")
    return rows


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()
