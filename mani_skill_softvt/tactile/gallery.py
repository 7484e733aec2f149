"""Tactile gallery: each asset's left-finger GelSight frame while it is held.

    python -m mani_skill_softvt.tactile.gallery [--out docs/tactile_gallery.png] [--closure C]

Runs the scripted grasp on ``SoftGraspLift-v1`` for each of the ten assets and the rigid twins
of the cube and the ball, at the middle of the asset's calibrated envelope (or ``--closure``),
lifts and stops 10 steps into the hold. Each tile stacks the tactile image (markers drawn, their
displacement from rest drawn as arrows magnified x5), the gel's shading change magnified x10
(the image against the no-contact background with the markers drawn where they are now: faint on
objects softer than the gel, the markers' motion is most of what the RGB carries), and the gel's
indentation as a heat map (its own scale, peak in micrometres) with the physical contact outlined
in white: the FEM surface at or past the pad (exact polygon clipping, what the tests check the
patch against).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from ..assets.cards import ASSET_IDS
from ..paths import REPO_DIR

ARROW_GAIN = 5.0  # the gel's outward flow and shear are 1-4 px
CHANGE_GAIN = 10.0
TWINS = ("rigid_stw_cube_hq", "rigid_stw_sphere_hq")


def envelope_middle(asset_id: str) -> float:
    """The middle of the asset's calibrated closure envelope (a twin uses its soft asset's card)."""
    from ..calibration.cards import load_calibration_card

    card = load_calibration_card(asset_id.replace("rigid_", "soft_"))
    return 0.5 * (card.g_min + card.g_max)


def held_frame(asset_id: str, closure: float, seed: int = 0):
    """The left finger's TactileFrame 10 steps into the hold of the calibration grasp, and the
    physical contact mask (240, 320) of that pad."""
    import gymnasium as gym

    from .. import tasks  # noqa: F401
    from ..calibration import protocol as P
    from ..calibration.grasp_script import GraspPlan, run_grasp_script

    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=asset_id)
    try:
        env.reset(seed=seed)
        run_grasp_script(env, GraspPlan(closure=closure, steps={**P.STEPS, "hold": 10}))
        u = env.unwrapped
        return u.tactile_frames()["left"], u.tactile_contact_reference("left")
    finally:
        env.close()


def heat_map(frame, contact: np.ndarray) -> np.ndarray:
    """The indentation as an RGB heat map on its own scale, the physical contact outlined."""
    peak = float(frame.depth.max())
    scaled = np.zeros(frame.depth.shape, np.uint8) if peak <= 0 else np.uint8(np.clip(frame.depth / peak, 0, 1) * 255)
    img = cv2.applyColorMap(scaled, cv2.COLORMAP_INFERNO)[..., ::-1].copy()
    outline, _ = cv2.findContours(contact.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, outline, -1, (255, 255, 255), 1)
    cv2.putText(img, f"peak {peak * 1e6:.0f} um, {frame.normal_force or 0.0:.1f} N", (6, 232),
                cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def shading_change(frame) -> np.ndarray:
    """|image - no-contact background with the markers where they are now| per channel, magnified,
    with its largest grey-level change written on it: the indentation's shading alone."""
    from .markers import draw_markers
    from .optics import load_optics

    background = draw_markers(load_optics().background, frame.marker_current)
    diff = np.abs(frame.image.astype(np.int16) - background.astype(np.int16))
    img = np.uint8(np.clip(diff * CHANGE_GAIN, 0, 255))
    cv2.putText(img, f"shading x{CHANGE_GAIN:.0f}, max {int(diff.max())} levels", (6, 232),
                cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return img


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
    ap.add_argument("--closure", type=float, default=None, help="default: the middle of each asset's envelope")
    args = ap.parse_args(argv)
    tiles = []
    for asset in tqdm(list(ASSET_IDS) + list(TWINS), desc="tactile gallery", unit="asset"):
        closure = envelope_middle(asset) if args.closure is None else args.closure
        frame, contact = held_frame(asset, closure)
        img = overlay(frame)
        cv2.putText(img, f"{asset} g={closure:.2f}", (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1,
                    cv2.LINE_AA)
        tiles.append(np.concatenate([img, shading_change(frame), heat_map(frame, contact)], axis=0))
    rows = [np.concatenate(tiles[i:i + 6], axis=1) for i in range(0, len(tiles), 6)]
    save_png(np.concatenate(rows, axis=0), args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
