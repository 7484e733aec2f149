"""Documentation images: the asset gallery and the tactile gallery.

    python -m mani_skill_softvt.cli.gallery assets [--out docs/asset_gallery.png] [--tile 256]
    python -m mani_skill_softvt.cli.gallery tactile [--out docs/tactile_gallery.png] [--closure C]

``assets``: each of the ten deformable assets and their rigid twins drawn from its card's visual
meshes (what the task cameras see) with SAPIEN's CPU renderer, one tile per asset, labelled with
id, size, mass and Young's modulus. Soft assets fill the top two rows, their rigid twins the
bottom two (same mesh, colour and mass; a twin is a PhysX rigid body, with no modulus).

``tactile``: each asset's left-finger GelSight frame while it is held. Runs the scripted grasp on
``SoftGraspLift-v1`` for each of the ten assets and the rigid twins of the cube and the ball, at
the middle of the asset's calibrated envelope (or ``--closure``), lifts and stops 10 steps into
the hold. Each tile stacks the tactile image (markers drawn, their displacement from rest drawn
as arrows magnified x5), the gel's shading change magnified x10 (the image against the
no-contact background with the markers drawn where they are now: faint on objects softer than
the gel, the markers' motion is most of what the RGB carries), and the gel's indentation as a
heat map (its own scale, peak in micrometres) with the physical contact outlined in white: the
FEM surface at or past the pad (exact polygon clipping, what the tests check the patch against).

Both are commands over the simulator and the renderer, so they live here at the command layer,
not inside the ``assets`` or ``tactile`` concepts they picture.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import sapien
from tqdm import tqdm

from .. import tasks  # noqa: F401  (registers the envs)
from ..assets.cards import ASSET_IDS, TWIN_IDS, AssetCard, load_card, read_obj
from ..assets.tetmesh import vertex_normals
from ..calibration import protocol as P
from ..calibration.cards import load_calibration_card
from ..data.images import write_png
from ..expert.grasp_script import GraspPlan, run_grasp_script
from ..paths import REPO_DIR
from ..tactile.markers import draw_markers
from ..tactile.optics import load_optics

SPACING = 0.3  # m between assets: far enough that no neighbour enters a tile's view
COLUMNS = 5


def _scene() -> sapien.Scene:
    scene = sapien.Scene([sapien.physx.PhysxCpuSystem(), sapien.render.RenderSystem(sapien.Device("cpu"))])
    scene.set_ambient_light([0.35, 0.35, 0.35])
    scene.add_directional_light([0.3, 0.6, -1.0], [0.9, 0.9, 0.9])
    scene.add_directional_light([-0.5, -0.2, -0.6], [0.3, 0.3, 0.3])
    ground = sapien.Entity()
    body = sapien.render.RenderBodyComponent()
    body.attach(sapien.render.RenderShapePlane(
        [1.0, 20.0, 20.0], sapien.render.RenderMaterial(base_color=[0.78, 0.76, 0.72, 1.0], roughness=0.9)))
    ground.add_component(body)
    ground.set_pose(sapien.Pose(q=[0.7071068, 0.0, -0.7071068, 0.0]))  # plane normal +x -> +z
    scene.add_entity(ground)
    return scene


def _add_asset(scene: sapien.Scene, card: AssetCard, xy: tuple[float, float]) -> None:
    body = sapien.render.RenderBodyComponent()
    for _, path, rgba in card.visual_parts:
        v, f = read_obj(path)
        body.attach(sapien.render.RenderShapeTriangleMesh(
            vertices=v.astype(np.float32), triangles=f.astype(np.uint32),
            normals=vertex_normals(v, f), uvs=np.zeros((len(v), 2), np.float32),
            material=sapien.render.RenderMaterial(base_color=list(rgba), roughness=0.7)))
    entity = sapien.Entity()
    entity.add_component(body)
    entity.set_pose(sapien.Pose(p=[xy[0], xy[1], 0.0]))
    scene.add_entity(entity)


def _label(card: AssetCard) -> list[str]:
    dx, dy, dz = (1e3 * np.asarray(card.dimensions)).round().astype(int)
    stiffness = "PhysX rigid body" if card.youngs_modulus is None else f"E={card.youngs_modulus / 1e3:g} kPa"
    return [card.asset_id, f"{dx}x{dy}x{dz} mm  {1e3 * card.mass:.1f} g", f"{card.kind}  {stiffness}"]


def asset_gallery(tile: int = 256) -> np.ndarray:
    """The gallery as an RGB uint8 image (4 rows x 5 columns of tiles)."""
    ids = list(ASSET_IDS) + list(TWIN_IDS)
    cards = [load_card(i) for i in ids]
    scene = _scene()
    cam_entity = sapien.Entity()
    camera = sapien.render.RenderCameraComponent(tile, tile)
    camera.set_fovy(np.deg2rad(35))
    cam_entity.add_component(camera)
    scene.add_entity(cam_entity)
    for k, card in enumerate(cards):
        _add_asset(scene, card, (SPACING * k, 0.0))
    tiles = []
    for k, card in enumerate(tqdm(cards, desc="gallery", unit="asset")):
        size = float(np.linalg.norm(card.dimensions))
        centre = np.array([SPACING * k, 0.0, 0.5 * card.dimensions[2]])
        eye = centre + 1.9 * size * np.array([-0.75, -0.45, 0.55]) / np.linalg.norm([-0.75, -0.45, 0.55])
        cam_entity.set_pose(sapien.Pose(p=eye, q=_look_at(centre - eye)))
        scene.update_render()
        camera.take_picture()
        rgb = (np.clip(camera.get_picture("Color")[..., :3], 0, 1) * 255).astype(np.uint8)
        rgb = np.ascontiguousarray(rgb)
        for j, line in enumerate(_label(card)):
            cv2.putText(rgb, line, (6, 16 + 15 * j), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (20, 20, 20), 1, cv2.LINE_AA)
        tiles.append(rgb)
    rows = [np.concatenate(tiles[r:r + COLUMNS], axis=1) for r in range(0, len(tiles), COLUMNS)]
    return np.concatenate(rows, axis=0)


def _look_at(forward: np.ndarray) -> np.ndarray:
    """wxyz quaternion of a SAPIEN camera (x forward, z up) looking along ``forward``."""
    x = forward / np.linalg.norm(forward)
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    return sapien.Pose(np.column_stack([np.column_stack([x, y, z]), [0, 0, 0]]).tolist() + [[0, 0, 0, 1]]).q


TACTILE_ARROW_GAIN = 5.0  # the gel's outward flow and shear are 1-4 px
TACTILE_CHANGE_GAIN = 10.0
TACTILE_TWINS = ("rigid_stw_cube_hq", "rigid_stw_sphere_hq")


def envelope_middle(asset_id: str) -> float:
    """The middle of the asset's calibrated closure envelope (a twin uses its soft asset's card)."""
    card = load_calibration_card(asset_id.replace("rigid_", "soft_"))
    return 0.5 * (card.g_min + card.g_max)


def held_frame(asset_id: str, closure: float, seed: int = 0):
    """The left finger's TactileFrame 10 steps into the hold of the calibration grasp, and the
    physical contact mask (240, 320) of that pad."""
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
    background = draw_markers(load_optics().background, frame.marker_current)
    diff = np.abs(frame.image.astype(np.int16) - background.astype(np.int16))
    img = np.uint8(np.clip(diff * TACTILE_CHANGE_GAIN, 0, 255))
    cv2.putText(img, f"shading x{TACTILE_CHANGE_GAIN:.0f}, max {int(diff.max())} levels", (6, 232),
                cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def overlay(frame) -> np.ndarray:
    img = frame.image.copy()
    for p0, p1 in zip(frame.marker_initial, frame.marker_current):
        tip = p0 + TACTILE_ARROW_GAIN * (p1 - p0)
        if np.linalg.norm(tip - p0) > 1.0:
            cv2.arrowedLine(img, tuple(np.round(p0).astype(int)), tuple(np.round(tip).astype(int)), (255, 255, 255), 1,
                            cv2.LINE_AA, tipLength=0.3)
    return img


def tactile_gallery(closure: float | None = None) -> np.ndarray:
    """The tactile gallery as an RGB uint8 image (two rows of six tiles)."""
    tiles = []
    for asset in tqdm(list(ASSET_IDS) + list(TACTILE_TWINS), desc="tactile gallery", unit="asset"):
        g = envelope_middle(asset) if closure is None else closure
        frame, contact = held_frame(asset, g)
        img = overlay(frame)
        cv2.putText(img, f"{asset} g={g:.2f}", (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1,
                    cv2.LINE_AA)
        tiles.append(np.concatenate([img, shading_change(frame), heat_map(frame, contact)], axis=0))
    rows = [np.concatenate(tiles[i:i + 6], axis=1) for i in range(0, len(tiles), 6)]
    return np.concatenate(rows, axis=0)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.cli.gallery", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="which", required=True)
    a = sub.add_parser("assets", help="the ten assets and their rigid twins")
    a.add_argument("--out", type=Path, default=REPO_DIR / "docs" / "asset_gallery.png")
    a.add_argument("--tile", type=int, default=256, help="tile size in pixels")
    t = sub.add_parser("tactile", help="each asset's GelSight frame while held (about 2 min)")
    t.add_argument("--out", type=Path, default=REPO_DIR / "docs" / "tactile_gallery.png")
    t.add_argument("--closure", type=float, default=None, help="default: the middle of each asset's envelope")
    args = ap.parse_args(argv)
    image = asset_gallery(args.tile) if args.which == "assets" else tactile_gallery(args.closure)
    write_png(args.out, image)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
