"""Tactile renderer speed: milliseconds per finger per frame, beside taxim's JAX backend.

    python benchmarks/bench_tactile.py [--frames 30]

Scenes are meshes pressed into one pad (a 10 mm sphere at three depths, a tilted 8 x 6 mm box,
a lying 3 mm cylinder). For each, at 320 x 240:

- ``hm->img+mk``: our height map -> image + markers (optics, marker field, dots);
- ``full``: our whole per-finger frame from world triangles and the pad pose (transform,
  rasterise, optics, shear/twist tracking, markers, dots);
- ``taxim jax``: taxim's JAX backend (``TaximJax.render``, no shadows) on the same height map,
  if jax is importable (optional: pip install 'mani-skill-softvt[bench]');
- ``MAD img``: mean absolute difference (0-255, over pixels and channels) between our image
  (no markers) and taxim's; ``MAD chg``: the same between what contact *changes* in each image
  (each minus its own no-contact frame), which factors out the two backgrounds: we add the
  colour change to the raw Mini frame, taxim to its smoothed frame plus its gel-dome shading;
  ``MAD chg@contact``: the latter over the pixels that either renderer changes visibly
  (|change| summed over RGB > 6), so the untouched rest of the image does not dilute it.
"""

from __future__ import annotations

import argparse
import time
from typing import Callable

import numpy as np
import trimesh

from mani_skill_softvt.tactile import TactileSensor, finger_pad_frame
from mani_skill_softvt.tactile import constants as C
from mani_skill_softvt.tactile.geometry import heightmap_from_triangles
from mani_skill_softvt.tactile.markers import draw_markers, marker_displacements
from mani_skill_softvt.tactile.optics import calibration_folder, render_image

JAX_MISSING = "jax not installed — pip install 'mani-skill-softvt[bench]'"


def scenes() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Name -> (vertices in the pad frame (m), faces): meshes pressed into the gel (z < 0)."""
    out = {}
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.01)
    for d in (0.2e-3, 0.6e-3, 1.2e-3):
        out[f"sphere R10 d{d * 1e3:.1f}mm ({len(sphere.faces)} tris)"] = (
            np.asarray(sphere.vertices) + [0.5e-3, -0.3e-3, 0.01 - d], np.asarray(sphere.faces))
    box = trimesh.creation.box(extents=(8e-3, 6e-3, 4e-3))
    box = box.subdivide().subdivide()  # finer triangles: the rasteriser sees a realistic count
    tilt = trimesh.transformations.rotation_matrix(np.deg2rad(3.0), [0, 1, 0])
    box.apply_transform(tilt)
    v = np.asarray(box.vertices)
    out[f"box 8x6 tilt3deg d0.5mm ({len(box.faces)} tris)"] = (v + [-2e-3, 1e-3, -v[:, 2].min() - 0.5e-3], np.asarray(box.faces))
    cyl = trimesh.creation.cylinder(radius=3e-3, height=12e-3, sections=64)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))  # axis along pad x
    v = np.asarray(cyl.vertices)
    out[f"cylinder R3 side d0.4mm ({len(cyl.faces)} tris)"] = (v + [0, 0, -v[:, 2].min() - 0.4e-3], np.asarray(cyl.faces))
    return out


def time_ms(fn: Callable[[int], object], frames: int) -> tuple[float, object]:
    """Mean wall time (ms) of fn(i) over ``frames`` calls after two warm-up calls (JIT, caches)."""
    fn(0)
    fn(1)
    t = time.perf_counter()
    for i in range(frames):
        out = fn(i)
    return 1e3 * (time.perf_counter() - t) / frames, out


def make_taxim():
    """taxim's JAX renderer on the CPU at its own GelSight Mini calibration, or None without jax.

    taxim's pixmm stays at the calibration's 0.0295 mm/px: taxim rescales slopes itself when
    given a height map smaller than 640 x 480 (its gradient is multiplied by shape / 480)."""
    try:
        import jax
        from taxim.taxim_jax import TaximJax
    except ImportError:
        return None
    return TaximJax(calib_folder=calibration_folder(), device=jax.devices("cpu")[0])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=30)
    args = ap.parse_args(argv)

    sensor = TactileSensor("left")
    bg = sensor.calib.background.astype(np.float64)
    taxim = make_taxim()
    taxim_bg = None
    if taxim is not None:
        # taxim's height map: mm from the gel's top, negative = pressed in; zeros = no contact.
        taxim_bg = 255.0 * np.asarray(taxim.render(np.zeros((C.IMAGE_HEIGHT, C.IMAGE_WIDTH), np.float32), with_shadow=False))
    # A pad somewhere in the world, tilted, so the full path includes the frame transform.
    pose = finger_pad_frame("left", np.array([0.4, -0.1, 0.3]), np.array([0.0, 0.6, 0.8]), np.array([1.0, 0.0, 0.0]))

    rows = []
    for name, (v_pad, faces) in scenes().items():
        pen = heightmap_from_triangles(v_pad, faces)

        def ours(_i: int) -> np.ndarray:
            img = render_image(pen, sensor.calib)
            xy = marker_displacements(sensor.marker_initial, pen, (1.5, -0.5), 0.01)
            draw_markers(img, xy)
            return img

        ms_ours, img_ours = time_ms(ours, args.frames)
        # Full frame: the mesh jitters by 20 um so shear tracking runs on every frame.
        worlds = [(v_pad + [dx, 0.0, 0.0]) @ pose[:3, :3].T + pose[:3, 3] for dx in (0.0, 20e-6)]
        sensor.reset()
        ms_full, _ = time_ms(lambda i: sensor.render(worlds[i % 2], faces, pose), args.frames)
        row = {"name": name, "ours": ms_ours, "full": ms_full, "tris": len(faces)}
        if taxim is not None:
            hm = (-1e3 * pen).astype(np.float32)
            ms_taxim, img_taxim = time_ms(lambda _i: np.asarray(taxim.render(hm, with_shadow=False)), args.frames)
            img_taxim = 255.0 * img_taxim
            chg_ours, chg_taxim = img_ours - bg, img_taxim - taxim_bg
            region = (np.abs(chg_ours).sum(axis=2) > 6) | (np.abs(chg_taxim).sum(axis=2) > 6)
            row.update(taxim=ms_taxim,
                       mad_img=float(np.abs(img_ours - img_taxim).mean()),
                       mad_chg=float(np.abs(chg_ours - chg_taxim).mean()),
                       mad_contact=float(np.abs(chg_ours - chg_taxim)[region].mean()))
        rows.append(row)

    print(f"\nTactile rendering at {C.IMAGE_WIDTH}x{C.IMAGE_HEIGHT}, {args.frames} frames each, "
          "ms per finger per frame (CPU)\n")
    print("| scene | ours hm->img+mk | ours full (tris->frame) | taxim jax (no shadow) | taxim / ours "
          "| MAD img | MAD chg | MAD chg@contact |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "taxim" in r:
            print(f"| {r['name']} | {r['ours']:.2f} | {r['full']:.2f} | {r['taxim']:.2f} | "
                  f"{r['taxim'] / r['ours']:.1f}x | {r['mad_img']:.2f} | {r['mad_chg']:.2f} | {r['mad_contact']:.2f} |")
        else:
            print(f"| {r['name']} | {r['ours']:.2f} | {r['full']:.2f} | - | - | - | - | - |")
    if taxim is None:
        print(f"| taxim jax | {JAX_MISSING} | | | | | | |")
    else:
        print(f"\nno-contact frames: ours (raw Mini frame) vs taxim's (smoothed frame + gel-dome shading): "
              f"MAD {float(np.abs(bg - taxim_bg).mean()):.2f}")
    print("MAD: mean absolute difference, 0-255 per channel; 'chg': of each image minus its own no-contact frame")


if __name__ == "__main__":
    main()
