"""Open-loop error of a trained baseline on held-out demonstrations: the recipe search's cheap measure.

    python -m softvt_campaign.studies.openloop outputs/baselines/object_soft/vo-c-cpu/policy.pt

A run trained with ``--set heldout_per_task=N`` never saw the last N demos of each task. At every
step where the agent would replan (every ``action_steps`` steps of an episode), the policy
denoises a chunk from the demo's own observations, and its executed actions are compared with
the expert's: the TCP position error (mm), the rotation between the two orientations (degrees)
and the gripper closure error, on the held-out demos and, for comparison, on as many training
windows. A policy whose held-out chunks are centimetres off will not grasp in closed loop; one
close to its training error generalises. Closed-loop TSR (``evaluate``) is the measure that
decides; this one costs seconds instead of hours. Writes ``openloop.json`` beside the policy.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from ..baselines.agent import GRIPPER, executed_actions, load_policy_file
from ..baselines.dataset import DemoWindows, load_windows
from ..baselines.model import noise_scheduler
from ..baselines.train import CACHE
from mani_skill_softvt.fileio import atomic_write_json
from mani_skill_softvt.paths import DEMOS_DIR


def action_errors(pred: np.ndarray, target: np.ndarray) -> dict[str, np.ndarray]:
    """Per action of (..., 7) base-frame actions (xyz, axis-angle, closure): the position error (m),
    the angle of the rotation between the two orientations (rad) and the closure error."""
    pred, target = np.asarray(pred, np.float64), np.asarray(target, np.float64)
    shape = pred.shape[:-1]
    rel = Rotation.from_rotvec(pred[..., 3:6].reshape(-1, 3)).inv() * Rotation.from_rotvec(target[..., 3:6].reshape(-1, 3))
    return {"position_m": np.linalg.norm(pred[..., :3] - target[..., :3], axis=-1),
            "rotation_rad": rel.magnitude().reshape(shape),
            "gripper": np.abs(pred[..., GRIPPER] - target[..., GRIPPER])}


def replan_indices(windows: DemoWindows, every: int, limit: int | None = None) -> np.ndarray:
    """The global step indices where the agent replans (steps 0, every, 2 every, ... of each
    episode), thinned evenly to at most ``limit``."""
    out = np.concatenate([np.arange(a, b, every) for a, b in zip(windows.act_starts[:-1], windows.act_starts[1:])])
    if limit is not None and len(out) > limit:
        out = out[np.linspace(0, len(out) - 1, limit).round().astype(int)]
    return out


def chunk_errors(model, windows: DemoWindows, indices: np.ndarray, seed: int = 0, batch: int = 64,
                 progress: bool = True) -> dict[str, np.ndarray]:
    """:func:`action_errors` of the actions the agent would execute (the first ``action_steps`` of
    each chunk the model denoises at ``indices``, its gripper column as the agent sends it) against
    the demonstrated ones; arrays (len(indices), action_steps)."""
    cfg = model.cfg
    scheduler = noise_scheduler(cfg, inference=True)
    generator = torch.Generator().manual_seed(seed)
    parts = []
    for i in tqdm(range(0, len(indices), batch), desc="open loop", unit="batch", disable=not progress, leave=False):
        obs, act = windows.batch(indices[i:i + batch])
        chunk = executed_actions(model.sample(obs, generator, scheduler).numpy(), cfg)
        parts.append(action_errors(chunk, act[:, :cfg.action_steps].numpy()))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def summarize_errors(errors: dict[str, np.ndarray]) -> dict[str, float]:
    """Means and medians in readable units (mm, degrees, closure), over all executed actions, and
    of the first action of each chunk (what the policy commits to next)."""
    pos, rot, grip = errors["position_m"] * 1e3, np.degrees(errors["rotation_rad"]), errors["gripper"]
    return {"windows": int(pos.shape[0]),
            "position_mm_mean": float(pos.mean()), "position_mm_median": float(np.median(pos)),
            "position_mm_first_action": float(pos[:, 0].mean()),
            "rotation_deg_mean": float(rot.mean()), "gripper_mean": float(grip.mean())}


def run_dir_of(policy_path: Path) -> Path:
    """The run directory of a ``policy.pt`` or of one of its snapshots (``<run>/snapshots/*.pt``):
    where the run's prepared data lies."""
    parent = Path(policy_path).parent
    return parent.parent if parent.name == "snapshots" else parent


def load_run_windows(cfg, run: Path, demos_root: Path, cache: Path | None = None) -> tuple[DemoWindows, DemoWindows]:
    """The held-out and training windows of the run in ``run``, through the data cache ``cache``
    (default: the run's own, ``<run>/data_cache``)."""
    cache = Path(run) / CACHE if cache is None else cache
    return load_windows(cfg, demos_root, cache, heldout=True), load_windows(cfg, demos_root, cache)


def openloop(policy_path: Path, demos_root: Path = DEMOS_DIR, limit: int = 500, threads: int = 2,
             progress: bool = True, write: bool = True, windows: tuple[DemoWindows, DemoWindows] | None = None,
             cache: Path | None = None) -> dict:
    """Held-out and training open-loop errors of a ``policy.pt`` or a snapshot (see the module
    docstring); ``write`` puts them in ``openloop.json`` beside it. ``windows``: the run's
    (held-out, training) windows when the caller has them (several snapshots of one run)."""
    policy_path = Path(policy_path)
    cfg, model, ckpt = load_policy_file(policy_path)
    if cfg.heldout_per_task < 1:
        raise ValueError(f"{policy_path} was trained on every demo (heldout_per_task=0): nothing is held out. Train "
                         "with `--set heldout_per_task=10` (the last 10 demos of each task are then never trained on)")
    torch.set_num_threads(threads)
    if cache is None and ckpt.get("data_cache") and Path(ckpt["data_cache"]).is_dir():
        cache = Path(ckpt["data_cache"])  # where its run prepared the data (a shared cache, say)
    heldout, training = windows or load_run_windows(cfg, run_dir_of(policy_path), demos_root, cache)
    if ckpt.get("data_key") not in (None, training.key):
        raise ValueError(f"{policy_path} was trained on other demos than {demos_root} now holds (its episodes "
                         "changed): the held-out ones might have been trained on. Measure it on the demos it was "
                         "trained on, or train again")
    out = {"policy": str(policy_path), "steps": ckpt.get("steps"), "train_wall_s": ckpt.get("train_wall_s"),
           "config": ckpt["config"], "episodes_trained": training.episodes,
           "episodes_heldout": heldout.episodes, "camera_render_size": list(heldout.camera_render_size)}
    for name, data in (("heldout", heldout), ("training", training)):
        idx = replan_indices(data, cfg.action_steps, limit)
        out[name] = summarize_errors(chunk_errors(model, data, idx, seed=cfg.seed, progress=progress))
    if write:
        atomic_write_json(policy_path.parent / "openloop.json", out)
    return out


def format_openloop(result: dict) -> str:
    head = f"{'demos':>9}  {'windows':>7}  {'pos mm':>7}  {'median':>7}  {'1st act':>7}  {'rot deg':>7}  {'gripper':>7}"
    title = (f"{result['policy']} ({result['steps']} steps; {result['episodes_trained']} demos trained on, "
             f"{result['episodes_heldout']} held out)")
    lines = [title, head]
    for name in ("heldout", "training"):
        r = result[name]
        lines.append(f"{name:>9}  {r['windows']:>7d}  {r['position_mm_mean']:7.1f}  {r['position_mm_median']:7.1f}  "
                     f"{r['position_mm_first_action']:7.1f}  {r['rotation_deg_mean']:7.2f}  {r['gripper_mean']:7.3f}")
    return "\n".join(lines)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m softvt_campaign.studies.openloop", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("policy", type=Path, help="a policy.pt of a run trained with heldout_per_task > 0")
    ap.add_argument("--demos", type=Path, default=DEMOS_DIR, help="demos root (generate + render output)")
    ap.add_argument("--windows", type=int, default=500, help="at most this many replanning steps per set")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=None,
                    help="the data cache to read (default: the one the run trained from, else <run>/data_cache)")
    args = ap.parse_args(argv)
    try:
        result = openloop(args.policy, args.demos, args.windows, args.threads, cache=args.cache)
    except (FileNotFoundError, ValueError) as e:
        ap.error(str(e))
    print(format_openloop(result))
    print(f"written: {args.policy.parent / 'openloop.json'}")
    return result


if __name__ == "__main__":
    main()
