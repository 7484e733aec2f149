"""Tactile gallery: each deformable asset's left-finger GelSight image at the moment of grasp.

    python -m mani_skill_softvt.tactile.gallery [--out docs/tactile_gallery.png] [--closure 0.8]

Runs the scripted grasp on ``SoftGraspLift-v1`` for each asset, stops when the gripper has
closed, and tiles the tactile images (markers drawn, their displacement from rest drawn as
arrows magnified x4) into one labelled PNG, like the paper's tactile figure.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from ..assets.cards import ASSET_IDS
from ..paths import REPO_DIR

ARROW_GAIN = 4.0


def grasp_frame(asset_id: str, closure: float, seed: int = 0):
    """The left finger's TactileFrame after the grasp closes on ``asset_id``."""
    import gymnasium as gym

    from .. import tasks  # noqa: F401
    from ..calibration.grasp_script import GraspPlan, run_grasp_script

    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=asset_id)
    try:
        env.reset(seed=seed)
        plan = GraspPlan(closure=closure)
        plan.steps = {**plan.steps, "lift": 0, "hold": 0, "lower": 0, "open": 0, "retreat": 0}
        run_grasp_script(env, plan)
        return env.unwrapped.tactile_frames()["left"]
    finally:
        env.close()


def overlay(frame) -> np.ndarray:
    img = frame.image.copy()
    for p0, p1 in zip(frame.marker_initial, frame.marker_current):
        tip = p0 + ARROW_GAIN * (p1 - p0)
        if np.linalg.norm(tip - p0) > 1.0:
            cv2.arrowedLine(img, tuple(np.round(p0).astype(int)), tuple(np.round(tip).astype(int)), (255, 255, 255), 1,
                            cv2.LINE_AA, tipLength=0.3)
    return img


def main(argv=None) -> None:
    from ..assets.gallery import save_png

    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.tactile.gallery", description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=REPO_DIR / "docs" / "tactile_gallery.png")
    ap.add_argument("--closure", type=float, default=0.8)
    args = ap.parse_args(argv)
    tiles = []
    for asset in tqdm(ASSET_IDS, desc="tactile gallery", unit="asset"):
        img = overlay(grasp_frame(asset, args.closure))
        cv2.putText(img, asset, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(img)
    rows = [np.concatenate(tiles[i:i + 5], axis=1) for i in range(0, len(tiles), 5)]
    save_png(np.concatenate(rows, axis=0), args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
