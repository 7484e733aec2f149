"""Compile and cache the Warp kernels (about 40 s once) so that the first real episode starts fast.

    python -m mani_skill_softvt.cli.warmup

Builds the foundation scene, steps it, and exits. Kernels land in ``WARP_CACHE_PATH``
(default ``~/.cache/mani_skill_softvt/warp``) and are reused by every later process.
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np

from .. import tasks  # noqa: F401  (registers the envs)
from ..contracts.actions import ee_action


def main() -> None:
    t0 = time.time()

    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose")
    env.reset(seed=0)
    xy = env.unwrapped.soft_nodes().mean(axis=0)[:2]
    for _ in range(2):
        env.step(ee_action(np.array([*xy, 0.1]), 0.0))
    env.close()
    print(f"[warmup] Warp kernels compiled and cached in {time.time() - t0:.1f} s")


if __name__ == "__main__":
    main()
