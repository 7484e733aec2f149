"""Tactile renderer speed: milliseconds per finger per frame, beside taxim's JAX backend.

    python benchmarks/bench_tactile.py [--frames 30]

Both renderers get the same height maps (a sphere pressed 0.2-1.2 mm, a flat-faced box pressed
0.5 mm with a tilt) at 320 x 240; taxim is told the matching pixel size. Prints a table with the
ratio and the mean absolute pixel difference (0-255) between the two images. taxim's JAX
backend is optional: pip install -e '.[bench]'.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import trimesh

from mani_skill_softvt.tactile import TactileSensor
from mani_skill_softvt.tactile import constants as C
from mani_skill_softvt.tactile.geometry import pixel_centers
from mani_skill_softvt.tactile.markers import marker_displacements
from mani_skill_softvt.tactile.optics import render_image


def height_maps() -> dict[str, np.ndarray]:
    """Object surface height above the gel (m) per pixel; negative = pressed into the gel."""
    xs, ys = pixel_centers()
    X, Y = np.meshgrid(xs, ys)
    maps = {}
    for d in (0.2e-3, 0.6e-3, 1.2e-3):
        r2 = X**2 + Y**2
        R = 0.01
        h = np.where(r2 < R * R, (R - d) - np.sqrt(np.maximum(R * R - r2, 0.0)), 5e-3)
        maps[f"sphere R10 d{d * 1e3:.1f}mm"] = h
    inside = (np.abs(X) < 4e-3) & (np.abs(Y) < 3e-3)
    maps["box 8x6 d0.5mm tilted"] = np.where(inside, -0.5e-3 + 0.05 * X, 5e-3)
    return maps


def time_it(fn, frames: int) -> float:
    fn()
    t = time.perf_counter()
    for _ in range(frames):
        out = fn()
    return 1e3 * (time.perf_counter() - t) / frames, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=30)
    args = ap.parse_args(argv)

    sensor = TactileSensor("left")
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.01)
    try:
        import jax

        from taxim.taxim_jax import TaximJax
        from importlib import resources

        folder = resources.files("taxim") / "calib" / "gelsight_mini"
        taxim = TaximJax(calib_folder=folder, params={"sensor": {"pixmm": C.PIXEL_SIZE * 1e3}},
                         device=jax.devices("cpu")[0])
    except ImportError:
        taxim = None

    rows = []
    if taxim is not None:
        # taxim's frame without contact: its processed background plus the flat-gel response.
        taxim_bg = np.asarray(taxim.render(np.full((C.IMAGE_HEIGHT, C.IMAGE_WIDTH), 5.0, np.float32), with_shadow=False))
        bg_mad = float(np.abs(255 * taxim_bg - sensor.calib.background).mean())
    for name, h in height_maps().items():
        pen = np.clip(-h, 0.0, C.MAX_PENETRATION)
        mask = pen > 0

        def ours():
            img = render_image(pen)
            marker_displacements(sensor.marker_initial, pen / C.PIXEL_SIZE, mask)
            return img
        ms_ours, img_ours = time_it(ours, args.frames)
        if taxim is not None:
            hm = (1e3 * np.maximum(h, -C.MAX_PENETRATION)).astype(np.float32)
            ms_taxim, img_taxim = time_it(lambda: np.asarray(taxim.render(hm, with_shadow=False)), args.frames)
            # Compare what contact changes: each image minus its own no-contact frame.
            change_taxim = 255 * (img_taxim - taxim_bg)
            change_ours = img_ours.astype(np.float64) - sensor.calib.background
            mad = float(np.abs(change_ours - change_taxim).mean())
            rows.append((name, ms_ours, ms_taxim, ms_taxim / ms_ours, mad))
        else:
            rows.append((name, ms_ours, None, None, None))
    # The full per-finger path: mesh rasterisation + optics + markers.
    v = np.asarray(sphere.vertices) + [0.0, 0.0, 0.01 - 0.6e-3]
    ms_full, _ = time_it(lambda: sensor.render_local(v, sphere.faces), args.frames)

    print(f"\nTactile rendering, {C.IMAGE_WIDTH}x{C.IMAGE_HEIGHT}, {args.frames} frames each (ms per finger per frame)\n")
    print("| height map | ours (optics+markers) | taxim JAX (no shadow) | taxim/ours | mean abs diff of the contact change |")
    print("|---|---|---|---|---|")
    for name, a, b, r, mad in rows:
        if b is None:
            print(f"| {name} | {a:.2f} | jax not installed: pip install -e '.[bench]' | - | - |")
        else:
            print(f"| {name} | {a:.2f} | {b:.2f} | {r:.1f}x | {mad:.2f} |")
    if taxim is not None:
        print(f"\nbackgrounds: ours (raw Mini frame) vs taxim's (processed, with the flat-gel response): "
              f"mean abs diff {bg_mad:.2f} (0-255)")
    print(f"\nfull sensor frame from a 5120-triangle sphere mesh (rasterise + optics + markers + dots): {ms_full:.2f} ms")


if __name__ == "__main__":
    main()
