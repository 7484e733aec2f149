"""Tactile rendering speed: milliseconds per finger per frame with contact, beside taxim's JAX backend.

    python benchmarks/bench_tactile.py [--frames 30] [--no-env]

Two kinds of scene, all with contact:

- **held grasps** (the env): the calibration grasp of three assets at the middle of their
  envelope, stopped 10 steps into the hold. ``env frame`` times ``env.tactile_frames()`` per
  finger: pad poses from SAPIEN, the FEM surface, the pad's normal force, the force-driven gel,
  optics, markers -- everything a ``+tactile`` observation costs per finger.
- **meshes** pressed into one pad at a prescribed depth (a 10 mm sphere, a tilted box, a lying
  cylinder): ``sensor frame`` times ``TactileSensor.render`` from world triangles.

``taxim jax`` times taxim's JAX renderer (``TaximJax.render``, no shadows; CPU) on the same
frame's height map at the same 320 x 240 (optional: ``pip install -e '.[bench]'``); ``ratio``
is taxim's time over ours. Our frame includes the rasterising, the gel and the markers; taxim's
renders only the image from a ready height map.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Callable

import numpy as np
import trimesh

from mani_skill_softvt.tactile import TactileSensor, finger_pad_frame
from mani_skill_softvt.tactile import constants as C
from mani_skill_softvt.tactile.optics import calibration_folder

JAX_MISSING = "jax not installed: pip install -e '.[bench]'"
GRASP_ASSETS = ("soft_stw_cube_hq", "soft_stw_sphere_hq", "soft_pastry001")


def mesh_scenes() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Name -> (vertices in the pad frame (m), faces): meshes pressed into the gel (z < 0)."""
    out = {}
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.01)
    for d in (0.2e-3, 1.2e-3):
        out[f"sphere R10 d{d * 1e3:.1f}mm ({len(sphere.faces)} tris)"] = (
            np.asarray(sphere.vertices) + [0.5e-3, -0.3e-3, 0.01 - d], np.asarray(sphere.faces))
    box = trimesh.creation.box(extents=(8e-3, 6e-3, 4e-3)).subdivide().subdivide()
    box.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(3.0), [0, 1, 0]))
    v = np.asarray(box.vertices)
    out[f"box 8x6 tilt3deg d0.5mm ({len(box.faces)} tris)"] = (v + [-2e-3, 1e-3, -v[:, 2].min() - 0.5e-3], np.asarray(box.faces))
    cyl = trimesh.creation.cylinder(radius=3e-3, height=12e-3, sections=64)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    v = np.asarray(cyl.vertices)
    out[f"cylinder R3 side d0.4mm ({len(cyl.faces)} tris)"] = (v + [0, 0, -v[:, 2].min() - 0.4e-3], np.asarray(cyl.faces))
    return out


def time_ms(fn: Callable[[int], object], frames: int) -> tuple[float, object]:
    """Median wall time (ms) of fn(i) over ``frames`` calls, after two warm-up calls (JIT, caches)."""
    fn(0)
    out = fn(1)
    times = []
    for i in range(frames):
        t = time.perf_counter()
        out = fn(i)
        times.append(time.perf_counter() - t)
    return 1e3 * float(np.median(times)), out


def make_taxim():
    """taxim's JAX renderer on the CPU at its GelSight Mini calibration, or None without jax."""
    try:
        import jax
        from taxim.taxim_jax import TaximJax
    except ImportError:
        return None
    return TaximJax(calib_folder=calibration_folder(), device=jax.devices("cpu")[0])


def time_taxim(taxim, depth: np.ndarray, frames: int) -> float | None:
    """taxim's time on our frame's indentation map (its height map: mm, negative = pressed in)."""
    if taxim is None:
        return None
    hm = (-1e3 * depth).astype(np.float32)
    return time_ms(lambda _i: np.asarray(taxim.render(hm, with_shadow=False)), frames)[0]


def held_grasp_envs():
    """(name, env) per grasp asset, held 10 steps into the hold at the middle of its envelope."""
    import gymnasium as gym

    import mani_skill_softvt  # noqa: F401
    from mani_skill_softvt.calibration import protocol as P
    from mani_skill_softvt.expert.grasp_script import GraspPlan, run_grasp_script
    from mani_skill_softvt.paths import CALIBRATION_DIR

    for asset in GRASP_ASSETS:
        card = json.loads((CALIBRATION_DIR / f"{asset}.json").read_text())
        closure = 0.5 * (card["g_min"] + card["g_max"])
        env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=asset)
        env.reset(seed=0)
        steps = {**P.STEPS, "hold": 10}
        run_grasp_script(env, GraspPlan(closure=closure, steps=steps))
        yield f"held grasp {asset} g={closure:.2f}", env


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--no-env", action="store_true", help="mesh scenes only (no simulation)")
    args = ap.parse_args(argv)
    taxim = make_taxim()
    rows = []
    if not args.no_env:
        for name, env in held_grasp_envs():
            u = env.unwrapped
            ms, frames = time_ms(lambda _i: u.tactile_frames(), args.frames)
            depth = frames["left"].depth
            rows.append((name + f" (F {u.pad_normal_force('left'):.1f} N)", ms / 2, time_taxim(taxim, depth, args.frames),
                         float((depth > C.CONTACT_THRESHOLD).sum() * C.PIXEL_SIZE ** 2 * 1e6)))
            env.close()
    sensor = TactileSensor("left")
    pose = finger_pad_frame("left", np.array([0.4, -0.1, 0.3]), np.array([0.0, 0.6, 0.8]), np.array([1.0, 0.0, 0.0]))
    for name, (v_pad, faces) in mesh_scenes().items():
        worlds = [(v_pad + [dx, 0.0, 0.0]) @ pose[:3, :3].T + pose[:3, 3] for dx in (0.0, 20e-6)]
        sensor.reset()
        ms, frame = time_ms(lambda i: sensor.render(worlds[i % 2], faces, pose), args.frames)
        rows.append((name, ms, time_taxim(taxim, frame.depth, args.frames),
                     float((frame.depth > C.CONTACT_THRESHOLD).sum() * C.PIXEL_SIZE ** 2 * 1e6)))

    print(f"\nTactile frame at {C.IMAGE_WIDTH}x{C.IMAGE_HEIGHT} with contact, median of {args.frames} frames, "
          "ms per finger (CPU, one process)\n")
    print("| scene | patch mm^2 | ours: whole frame | taxim jax: image only | taxim / ours |")
    print("|---|---|---|---|---|")
    for name, ours, tax, area in rows:
        tx = "-" if tax is None else f"{tax:.2f}"
        ratio = "-" if tax is None else f"{tax / ours:.2f}x"
        print(f"| {name} | {area:.0f} | {ours:.2f} | {tx} | {ratio} |")
    if taxim is None:
        print(f"\ntaxim jax: {JAX_MISSING}")


if __name__ == "__main__":
    main()
