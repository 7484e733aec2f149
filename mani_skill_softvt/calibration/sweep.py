"""One calibration trial in simulation, and a resumable sweep over closures for one asset.

Thin glue: the scripted grasp of :mod:`mani_skill_softvt.calibration.grasp_script` on
``SoftGraspLift-v1`` with the asset; the statistics live in :mod:`.stats`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data.seeds import calibration_seed
from ..fileio import append_jsonl, read_jsonl
from ..physics.constants import physics_signature, signature_mismatch
from ..physics.transforms import yaw_between
from . import protocol as P
from .stats import slip_distance


def run_trial(env, closure: float, seed: int, youngs_modulus_scale: float = 1.0) -> dict:
    """Grasp at ``closure``, lift, hold 2 s; report held/slip, peak D and the jaw aperture."""
    from .grasp_script import GraspPlan, run_grasp_script

    env.reset(seed=seed, options={"youngs_modulus_scale": youngs_modulus_scale})
    u = env.unwrapped
    rng = np.random.default_rng(seed)
    offset = rng.uniform(-P.JITTER_XY, P.JITTER_XY, 2)
    yaw = yaw_between(u.rest_vertices("object"), u.settled_nodes("object")) + rng.uniform(-P.JITTER_YAW, P.JITTER_YAW)
    plan = GraspPlan(closure=float(closure), yaw=float(yaw), steps=dict(P.STEPS))
    lift_end = P.STEPS["approach"] + P.STEPS["descend"] + P.STEPS["close"] + P.STEPS["lift"]
    count = [0]

    def on_step(phase, i, n):
        count[0] += 1
        # Not lifted at the end of the lift phase: the hold cannot change the verdict.
        if count[0] == lift_end and u.soft_nodes().min(axis=0)[2] < P.LIFT_THRESHOLD:
            return "stop"

    rec = run_grasp_script(env, plan, on_step=on_step, xy_offset=offset)
    hold = rec["phase"] == "hold"
    lifted = bool(hold.any() and rec["object_min_z"][hold][-1] >= P.LIFT_THRESHOLD)
    slip = slip_distance(rec["object_centroid"][hold], rec["tcp"][hold], rec["tcp_quat"][hold]) if lifted else None
    closed = rec["phase"] == "close"
    aperture = rec["gripper_width"][hold].mean() if lifted else rec["gripper_width"][closed][-1]
    return {
        "closure": float(closure), "seed": int(seed), "held": bool(lifted and slip <= P.SLIP_THRESHOLD),
        "lifted": lifted, "slip_mm": None if slip is None else 1e3 * slip,
        "peak_deformation": float(rec["deformation"].max()), "aperture_mm": 1e3 * float(aperture),
        "pad_force_n": float(np.mean(rec["pad_force"][hold])) if lifted else float(rec["pad_force"][closed][-1]),
    }


def sweep_asset(asset_id: str, asset_index: int, closures, repeats: int, log_path: Path, progress=None) -> list[dict]:
    """Run every (closure, repeat) trial not yet in ``log_path``; return all records.

    Each finished trial is appended to the JSONL log at once, so an interrupted sweep resumes
    where it stopped and never repeats or loses a trial. A log whose trials ran under other
    physics (:func:`physics_signature`) is refused rather than mixed into the new card.
    """
    import gymnasium as gym

    from .. import tasks  # noqa: F401  (registers SoftGraspLift-v1)

    previous = read_jsonl(log_path)
    stale = sorted({d for r in previous for d in signature_mismatch(r.get("physics"))})
    if stale:
        raise ValueError(f"sweep log {log_path} holds trials run under other physics ({'; '.join(stale)}); "
                         "move it away to recalibrate from scratch (python -m mani_skill_softvt.calibrate "
                         f"--restart --assets {asset_id} does that)")
    done = {(round(r["closure"], 6), r["repeat"]) for r in previous}
    todo = [(g, k) for g in closures for k in range(repeats) if (round(g, 6), k) not in done]
    if progress is not None:
        progress(len(closures) * repeats - len(todo), len(closures) * repeats)
    if todo:
        env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=asset_id)
        try:
            for g, k in todo:
                rec = run_trial(env, g, calibration_seed(asset_index, g, k))
                rec.update(asset_id=asset_id, repeat=k, physics=physics_signature())
                append_jsonl(log_path, rec)
                if progress is not None:
                    progress(1, None)
        finally:
            env.close()
    records = [r for r in read_jsonl(log_path) if round(r["closure"], 6) in {round(g, 6) for g in closures}]
    return sorted(records, key=lambda r: (r["closure"], r["repeat"]))
