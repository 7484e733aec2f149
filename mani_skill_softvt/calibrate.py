"""Per-object calibration: gripper envelope [g_min, g_max] and deformation tolerance tau_o.

    python -m mani_skill_softvt.calibrate                       # all ten deformable assets
    python -m mani_skill_softvt.calibrate --assets soft_stw_cube_hq --workers 1
    python -m mani_skill_softvt.calibrate --quick               # one asset, four closures, one repeat

For each asset: the scripted grasp, lift and 2 s hold at every closure from loose to tight,
several repeats with small pose jitter; slip is measured from the object's motion relative to
the hand. Writes ``calibration/<asset>.json`` (card with every sweep record, so any percentile
can be recomputed), ``calibration/plots/<asset>.png`` and ``calibration/plots/summary.png``.
Interrupted runs resume: finished trials are kept in ``calibration/.sweeps/<asset>.jsonl``.
Trials and cards record the physics constants they ran under; after the physics changed,
``--restart`` sets the old logs aside (``.sweeps/replaced/``) and sweeps from scratch.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from . import tasks  # noqa: F401  (registers SoftGraspLift-v1)
from .assets.cards import ASSET_IDS
from .calibration import protocol as P
from .calibration.cards import CalibrationCard, load_calibration_card, make_card, write_card
from .calibration.plots import plot_card, plot_summary
from .calibration.stats import slip_distance
from .data.seeds import calibration_seed
from .expert.grasp_script import GraspPlan, run_grasp_script
from .fileio import append_jsonl, read_jsonl
from .parallel import run_tasks
from .paths import CALIBRATION_DIR, writable_default
from .physics.constants import physics_signature, signature_mismatch
from .physics.transforms import yaw_between

QUICK_ASSET = "soft_stw_cube_hq"
QUICK_CLOSURES = (0.3, 0.5, 0.7, 0.9)


# ------------------------------------------------------------- one trial, one asset's sweep
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
                rec.update(asset_id=asset_id, repeat=k, physics=physics_signature())
                append_jsonl(log_path, rec)
                if progress is not None:
                    progress(1, None)
        finally:
            env.close()
    records = [r for r in read_jsonl(log_path) if round(r["closure"], 6) in {round(g, 6) for g in closures}]
    return sorted(records, key=lambda r: (r["closure"], r["repeat"]))


# ------------------------------------------------------------------------- the command
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


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.calibrate", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--assets", nargs="+", default=None, help=f"deformable asset ids (default: all ten; quick: {QUICK_ASSET})")
    ap.add_argument("--workers", type=int, default=1, help="assets calibrated in parallel processes")
    ap.add_argument("--ray", metavar="ADDRESS", default=None,
                    help="calibrate the assets as Ray tasks instead ('local', 'auto' or ray://host:10001); "
                         "on several nodes --out must be on a shared filesystem")
    ap.add_argument("--repeats", type=int, default=None, help=f"trials per closure (default {P.REPEATS}; quick {P.QUICK_REPEATS})")
    ap.add_argument("--closures", type=float, nargs="+", default=None, help="closures to sweep (default: 0.10 to 1.0 by 0.05)")
    ap.add_argument("--percentile", type=float, default=P.PERCENTILE)
    ap.add_argument("--quick", action="store_true", help="one asset, four closures, one repeat (smoke test)")
    ap.add_argument("--out", type=Path, default=None,
                    help=f"cards, plots and sweep logs (default {CALIBRATION_DIR}: $SOFTVT_CALIBRATION_DIR, else the "
                         "checkout's calibration/; needed to calibrate when the package is installed)")
    ap.add_argument("--restart", action="store_true",
                    help="set the assets' sweep logs aside (.sweeps/replaced/) and sweep from scratch, e.g. after "
                         "the physics changed; without it an interrupted run resumes")
    ap.add_argument("--table", action="store_true", help="print the cards in --out beside the paper's, then exit")
    args = ap.parse_args(argv)
    if args.table:  # reads only: the installed cards will do
        print(comparison_table(args.out if args.out is not None else CALIBRATION_DIR))
        return []
    try:
        args.out = args.out if args.out is not None else writable_default(CALIBRATION_DIR, "--out", "SOFTVT_CALIBRATION_DIR")
    except ValueError as e:
        ap.error(str(e))

    assets = args.assets or ([QUICK_ASSET] if args.quick else list(ASSET_IDS))
    unknown = [a for a in assets if a not in ASSET_IDS]
    if unknown:
        ap.error(f"unknown or non-deformable assets {unknown}; choose from {list(ASSET_IDS)}")
    closures = tuple(args.closures or (QUICK_CLOSURES if args.quick else P.CLOSURES))
    if any(not 0.0 <= g <= 1.0 for g in closures):
        ap.error(f"closures must lie in [0, 1], got {closures}")
    repeats = args.repeats or (P.QUICK_REPEATS if args.quick else P.REPEATS)
    if args.workers < 1:
        ap.error("--workers must be >= 1")

    if args.restart:
        for a in assets:
            set_aside(Path(args.out) / ".sweeps" / f"{a}.jsonl")
    total = len(assets) * len(closures) * repeats

    bar = tqdm(total=total, desc="calibration trials", unit="trial")
    cards = []
    out = Path(args.out).resolve()  # workers (Ray's above all) need not share our working directory
    items = [(a, closures, repeats, args.percentile, out) for a in assets]
    for kind, value in run_tasks(calibrate_asset, items, args.workers, args.ray):
        if kind == "message":  # (asset, trials just done, total)
            bar.update(value[1])
            bar.set_postfix_str(value[0])
        else:  # a worker's error is re-raised by run_tasks with its traceback
            cards.append(value)
            tqdm.write(_row(value))
    bar.close()
    if len(assets) > 1 or not args.quick:
        all_cards = []
        for a in ASSET_IDS:
            try:
                all_cards.append(load_calibration_card(a, args.out))
            except FileNotFoundError:
                pass
        plot_summary(all_cards, Path(args.out) / "plots" / "summary.png")
    return cards


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


def _row(card) -> str:
    return (f"{card.asset_id:22s} g_min {card.g_min:.2f}  g_max {card.g_max:.2f}  "
            f"span {card.span_mm:5.1f} mm  tau_o {100 * card.tau_o:.2f} % diag")


if __name__ == "__main__":
    main()
