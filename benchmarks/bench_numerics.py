"""What the pinned numerics cost: each workload under ``x86-64-v3`` against this machine's native dispatch.

    .venv/bin/python benchmarks/bench_numerics.py [--steps 20] [--frames 30]

Every row is measured under both numerics in the same run, each in a fresh process (the CPU
dispatch is chosen as the libraries load; ``SOFTVT_NUMERICS``, mani_skill_softvt/provenance/numerics.py),
the two alternating so that whatever else runs on the machine loads both alike:

- ``soft episode``, ``rigid episode``: wall seconds per simulated second of the scripted expert on
  Object-Soft / Object-Rigid task 3 (obs_mode state_dict), as in ``bench_episodes.py``;
- ``tactile frame``: ms per ``TactileSensor.render_local`` of a sphere pressed into the pad;
- ``DP chunk``, ``DP train step``: ms per denoised chunk (batch 1) and per optimiser step
  (batch 32) of the ``cpu`` preset's VT-C in its bfloat16 autocast, one thread, as in
  ``bench_train_step.py``.

``pinned / native`` is the ratio of the two in this run. On a machine whose native dispatch is
x86-64-v3 (AVX2 and FMA, no AVX-512) the ratio is 1 by construction; on an AVX-512 machine it is
what the portable bits cost there.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROWS = ("soft episode", "rigid episode", "tactile frame", "DP chunk", "DP train step")


def tactile_ms(frames: int) -> float:
    import trimesh

    from mani_skill_softvt.tactile import TactileSensor

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.005)
    v, f = np.asarray(sphere.vertices) + [0.0, 0.0, 0.005 - 0.4e-3], np.asarray(sphere.faces)
    sensor = TactileSensor("left")
    sensor.render_local(v, f, normal_force=2.0)
    t0 = time.perf_counter()
    for _ in range(frames):
        sensor.render_local(v, f, normal_force=2.0)
    return 1e3 * (time.perf_counter() - t0) / frames


def child(steps: int, frames: int) -> dict:
    """The rows under this process's numerics (run with SOFTVT_NUMERICS set)."""
    sys.path.insert(0, HERE)
    import torch

    from bench_episodes import expert_episode  # same directory
    from bench_train_step import time_setting

    from mani_skill_softvt.provenance.numerics import resolved

    torch.set_num_threads(1)
    out = {"numerics": resolved()["name"]}
    out["soft episode"] = expert_episode("object_soft", True)[0]
    out["rigid episode"] = expert_episode("object_rigid", True)[0]
    out["tactile frame"] = tactile_ms(frames)
    step_ms, chunk_ms, _ = time_setting("vt-c", "bf16", True, steps, 5)
    out["DP chunk"], out["DP train step"] = chunk_ms, step_ms
    return out


def measure(numerics: str, steps: int, frames: int) -> dict:
    env = {**os.environ, "SOFTVT_NUMERICS": numerics}
    done = subprocess.run([sys.executable, __file__, "--child", "--steps", str(steps), "--frames", str(frames)],
                          env=env, check=True, capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=20, help="timed DP training steps")
    ap.add_argument("--frames", type=int, default=30, help="timed tactile frames")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.steps, args.frames)))
        return
    runs = {"native": [], "x86-64-v3": []}
    for i, numerics in enumerate(["native", "x86-64-v3", "native", "x86-64-v3"]):
        print(f"[{i + 1}/4] {numerics}", file=sys.stderr, flush=True)
        runs[numerics].append(measure(numerics, args.steps, args.frames))
    best = {n: {row: min(r[row] for r in rs) for row in ROWS} for n, rs in runs.items()}
    units = {"soft episode": "wall s / sim s", "rigid episode": "wall s / sim s", "tactile frame": "ms",
             "DP chunk": "ms", "DP train step": "ms"}
    print("| row | unit | native | pinned (x86-64-v3) | pinned / native |")
    print("|---|---|---|---|---|")
    for row in ROWS:
        n, p = best["native"][row], best["x86-64-v3"][row]
        print(f"| {row} | {units[row]} | {n:.3g} | {p:.3g} | {p / n:.2f} |")
    print("(the faster of two runs each; native and pinned alternate)")


if __name__ == "__main__":
    main()
