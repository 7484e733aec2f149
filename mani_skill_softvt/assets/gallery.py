"""Render the ten deformable assets and their rigid twins into one labelled image.

    python -m mani_skill_softvt.assets.gallery [--out docs/asset_gallery.png] [--tile 256]

Each asset is drawn from its card's visual meshes (what the task cameras see) with SAPIEN's
CPU renderer, one tile per asset, labelled with id, size, mass and Young's modulus. Soft
assets fill the top two rows, their rigid twins the bottom two (same mesh, colour and mass; a
twin is a PhysX rigid body, with no modulus).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import sapien
from tqdm import tqdm

from ..fileio import atomic_write
from ..paths import REPO_DIR
from .cards import ASSET_IDS, TWIN_IDS, AssetCard, load_card, read_obj

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
            normals=_vertex_normals(v, f), uvs=np.zeros((len(v), 2), np.float32),
            material=sapien.render.RenderMaterial(base_color=list(rgba), roughness=0.7)))
    entity = sapien.Entity()
    entity.add_component(body)
    entity.set_pose(sapien.Pose(p=[xy[0], xy[1], 0.0]))
    scene.add_entity(entity)


def _vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    return (n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)).astype(np.float32)


def _label(card: AssetCard) -> list[str]:
    dx, dy, dz = (1e3 * np.asarray(card.dimensions)).round().astype(int)
    stiffness = "PhysX rigid body" if card.youngs_modulus is None else f"E={card.youngs_modulus / 1e3:g} kPa"
    return [card.asset_id, f"{dx}x{dy}x{dz} mm  {1e3 * card.mass:.1f} g", f"{card.kind}  {stiffness}"]


def render_gallery(tile: int = 256) -> np.ndarray:
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


def save_png(image: np.ndarray, out: Path) -> None:
    """Write an RGB image as PNG, atomically."""
    def write(tmp: Path):
        if not cv2.imwrite(str(tmp), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
            raise OSError(f"could not write {out}")
    atomic_write(Path(out), write)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.assets.gallery", description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=REPO_DIR / "docs" / "asset_gallery.png")
    ap.add_argument("--tile", type=int, default=256, help="tile size in pixels")
    args = ap.parse_args(argv)
    save_png(render_gallery(args.tile), args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
