"""Foundation demo: a Panda grasps a soft cube, lifts it, holds it, and puts it back down.

    python -m mani_skill_softvt.cli.grasp_demo                # defaults: seed 0, binary (force-limited) close
    python -m mani_skill_softvt.cli.grasp_demo --closure 0.6  # continuous closure target in [0, 1]

Prints the peak normalised deformation D, the lift height and the slip during the hold, and
writes an image strip (one frame per phase) and, with ``--video``, an mp4 of the episode.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
from tqdm import tqdm

from .. import tasks  # noqa: F401  (registers the envs)
from ..expert.grasp_script import GraspPlan, run_grasp_script
from ..fileio import atomic_write


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.cli.grasp_demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--closure", type=float, default=1.0, help="gripper closure in [0,1]; 1 = close until the force limit")
    ap.add_argument("--out", type=Path, default=Path("outputs/demo"))
    ap.add_argument("--video", action="store_true", help="also write an mp4 (renders every control step)")
    args = ap.parse_args(argv)


    t0 = time.time()
    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", render_mode="rgb_array")
    env.reset(seed=args.seed)
    if not 0.0 <= args.closure <= 1.0:
        ap.error(f"--closure must lie in [0, 1], got {args.closure}")
    plan = GraspPlan(closure=args.closure)
    frames, phase_end = [], {}
    bar = tqdm(total=sum(plan.steps.values()), desc="grasp-lift-hold-place", unit="step")

    def on_step(phase, i, n):
        bar.update(1)
        bar.set_postfix_str(phase)
        if args.video or i == n - 1:  # rendering on CPU costs ~50 ms: only when needed
            frame = env.render()[0].cpu().numpy()
            frames.append(frame)
            phase_end[phase] = frame

    rec = run_grasp_script(env, plan, on_step=on_step)
    bar.close()
    hold = rec["phase"] == "hold"
    lift_height = float(rec["object_min_z"][hold].min())
    slip = float(np.linalg.norm((rec["object_centroid"][hold] - rec["tcp"][hold])[-1] - (rec["object_centroid"][hold] - rec["tcp"][hold])[0]))
    result = {
        "peak_deformation": float(rec["deformation"].max()),
        "lift_height_m": lift_height,
        "hold_slip_m": slip,
        "grasp_width_m": float(rec["gripper_width"][hold].mean()),
        "wall_time_s": time.time() - t0,
    }
    out = args.out
    strip_img = np.concatenate([phase_end[p] for p in plan.steps if p in phase_end], axis=1)
    atomic_write(out / "grasp_strip.png", lambda p: imageio.imwrite(p, strip_img))
    if args.video:
        atomic_write(out / "grasp.mp4", lambda p: imageio.mimwrite(p, frames, fps=20, macro_block_size=1))
    print("peak normalised deformation D_max = {peak_deformation:.4f}".format(**result))
    print("lift height (lowest node, hold) = {:.1f} mm, slip over the hold = {:.2f} mm, jaw gap = {:.1f} mm".format(
        lift_height * 1e3, slip * 1e3, result["grasp_width_m"] * 1e3))
    print(f"wrote {out / 'grasp_strip.png'}" + (f" and {out / 'grasp.mp4'}" if args.video else ""))
    env.close()
    return result


if __name__ == "__main__":
    main()
