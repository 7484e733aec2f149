"""Observation cost of each obs mode, beside PickCube-v1 in the same mode, same run.

    .venv/bin/python benchmarks/bench_obs_modes.py [--frames 10] [--size 224]

One row per camera mode: milliseconds per observation (``env.get_obs()``, the robot at rest after a
reset: what each env step adds for its observation) of Object-Soft task 3 (two cameras, the soft
object drawn from its FEM nodes) and of PickCube-v1 (one camera) in that mode, with the cameras at
``--size``. ``ratio`` divides SoftVT's per-camera cost by PickCube-v1's; ``x rgb`` is each mode's
SoftVT cost over its ``rgb`` cost. The ``+tactile`` column adds both GelSights (two 240x320 frames),
which PickCube-v1 has no counterpart for. CPU, one process, the pinned numerics.
"""

from __future__ import annotations

import argparse

import numpy as np
from bench_render import pickcube_obs, softvt_obs  # the same measurements, one mode more (run as a script)

MODES = ("rgb", "depth", "segmentation", "rgbd", "rgb+depth+segmentation", "pointcloud", "sensor_data", "rgb+normal")


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--size", type=int, default=224, help="camera size (square)")
    args = ap.parse_args(argv)
    import mani_skill_softvt  # noqa: F401  (pins the numerics first)

    rows = []
    for mode in MODES:
        base = pickcube_obs(args.size, args.frames, mode)
        ms = softvt_obs(mode, args.size, args.frames)
        touch = softvt_obs(f"{mode}+tactile", args.size, args.frames)
        rows.append({"mode": mode, "pickcube_ms": base, "softvt_ms": ms, "tactile_ms": touch, "ratio": ms / 2 / base})
    rgb = rows[0]["softvt_ms"]
    print(f"{'obs mode':26s} {'PickCube-v1':>12s} {'SoftVT':>8s} {'ratio':>6s} {'x rgb':>6s} {'+tactile':>9s}")
    for r in rows:
        print(f"{r['mode']:26s} {r['pickcube_ms']:9.1f} ms {r['softvt_ms']:5.1f} ms {r['ratio']:6.2f} "
              f"{r['softvt_ms'] / rgb:6.2f} {r['tactile_ms']:6.1f} ms")
    print(f"cameras at {args.size}x{args.size}; ratio: SoftVT per camera (2) over PickCube-v1's one, same mode")
    return rows


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()
