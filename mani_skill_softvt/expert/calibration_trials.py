"""The calibration's trials and sweeps: the scripted grasp, lift and hold (:mod:`.grasp_script`) at
each closure, measured (held, slip, peak deformation, jaw aperture), swept over closures and
repeats per asset, resumable, and made into the asset's card (:mod:`mani_skill_softvt.calibration`,
pure: the protocol, the statistics and the card). The command is ``python -m mani_skill_softvt.calibrate``
(:mod:`mani_skill_softvt.cli.calibrate`).
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from .. import tasks  # noqa: F401  (registers SoftGraspLift-v1)
from ..assets.cards import ASSET_IDS
from ..calibration import protocol as P
from ..calibration.cards import CalibrationCard, load_calibration_card, make_card, write_card
from ..calibration.plots import plot_card, plot_summary
from ..calibration.stats import slip_distance
from ..data.seeds import calibration_seed
from ..fileio import append_jsonl, read_jsonl
from ..paths import CALIBRATION_DIR
from ..physics.config import physics_signature, signature_mismatch
from ..physics.transforms import yaw_between
from .grasp_script import GraspPlan, run_grasp_script


def run_trial(env, closure: float, seed: int, youngs_modulus_scale: float = 1.0) -> dict:
    """Grasp at ``closure``, lift, hold 2 s; report held/slip, peak D and the jaw aperture."""
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
                rec.update(asset_id=asset_id, repeat=k, physics=env.unwrapped.physics.signature())
                append_jsonl(log_path, rec)
                if progress is not None:
                    progress(1, None)
        finally:
            env.close()
    records = [r for r in read_jsonl(log_path) if round(r["closure"], 6) in {round(g, 6) for g in closures}]
    return sorted(records, key=lambda r: (r["closure"], r["repeat"]))


def calibrate_asset(asset_id: str, closures=P.CLOSURES, repeats: int = P.REPEATS, percentile: float = P.PERCENTILE,
                    out: Path = CALIBRATION_DIR, queue=None, write: bool = True) -> dict:
    """Sweep one asset (resuming from its log) and write its card and plot; return the card."""
    out = Path(out)
    log = out / ".sweeps" / f"{asset_id}.jsonl"

    def progress(n, total):
        if queue is not None:
            queue.put((asset_id, n, total))

    records = sweep_asset(asset_id, ASSET_IDS.index(asset_id), closures, repeats, log, progress)
    card = CalibrationCard.from_dict(make_card(asset_id, records, percentile, closures, repeats), f"card of {asset_id}")
    if write:
        write_card(card.data, out)
        plot_card(card, out / "plots" / f"{asset_id}.png")
    return card


def plot_all_cards(directory: Path) -> Path:
    """``plots/summary.png`` in ``directory``: every asset's card found there, side by side."""
    cards = []
    for a in ASSET_IDS:
        try:
            cards.append(load_calibration_card(a, directory))
        except FileNotFoundError:
            pass
    path = Path(directory) / "plots" / "summary.png"
    plot_summary(cards, path)
    return path


def set_aside(log: Path) -> Path | None:
    """Move a sweep log to ``replaced/`` beside it under the first free name; never overwrites."""
    if not log.exists():
        return None
    k = 0
    while (target := log.parent / "replaced" / f"{log.stem}.{k}.jsonl").exists():
        k += 1
    target.parent.mkdir(parents=True, exist_ok=True)
    log.rename(target)
    return target


def comparison_table(directory: Path = CALIBRATION_DIR) -> str:
    """Markdown table of the committed cards beside the paper's values."""
    lines = ["| asset | g_min | g_max | span mm | tau_o % diag | paper g_min | paper g_max | paper span mm | paper tau_o % |",
             "|---|---|---|---|---|---|---|---|---|"]
    for a in ASSET_IDS:
        try:
            c = load_calibration_card(a, directory)
        except FileNotFoundError:
            continue
        pg = P.PAPER_CARDS[a]
        lines.append(f"| {a} | {c.g_min:.2f} | {c.g_max:.2f} | {c.span_mm:.1f} | {100 * c.tau_o:.2f} | "
                     f"{pg[0]:.2f} | {pg[1]:.2f} | {pg[2]:.1f} | {pg[3]:.1f} |")
    return "\n".join(lines)
