"""Per-object calibration, the command: gripper envelope [g_min, g_max] and deformation tolerance tau_o.

    python -m mani_skill_softvt.calibrate                       # all ten deformable assets
    python -m mani_skill_softvt.calibrate --assets soft_stw_cube_hq --workers 1
    python -m mani_skill_softvt.calibrate --quick               # one asset, four closures, one repeat

For each asset: the scripted grasp, lift and 2 s hold at every closure from loose to tight,
several repeats with small pose jitter; slip is measured from the object's motion relative to
the hand. Writes ``calibration-data/<asset>.json`` (card with every sweep record, so any percentile
can be recomputed), ``calibration-data/plots/<asset>.png`` and ``calibration-data/plots/summary.png``.
Interrupted runs resume: finished trials are kept in ``calibration-data/.sweeps/<asset>.jsonl``.
Trials and cards record the physics constants they ran under; after the physics changed,
``--restart`` sets the old logs aside (``.sweeps/replaced/``) and sweeps from scratch. The trials
and sweeps are :mod:`mani_skill_softvt.expert.calibration_trials`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from ..assets.cards import ASSET_IDS
from ..calibration import protocol as P
from ..expert.calibration_trials import calibrate_asset, comparison_table, plot_all_cards, set_aside
from ..parallel import run_tasks
from ..paths import CALIBRATION_DIR, writable_default

QUICK_ASSET = "soft_stw_cube_hq"
QUICK_CLOSURES = (0.3, 0.5, 0.7, 0.9)


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
                         "checkout's calibration-data/; needed to calibrate when the package is installed)")
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
        plot_all_cards(args.out)
    return cards


def _row(card) -> str:
    return (f"{card.asset_id:22s} g_min {card.g_min:.2f}  g_max {card.g_max:.2f}  "
            f"span {card.span_mm:5.1f} mm  tau_o {100 * card.tau_o:.2f} % diag")


if __name__ == "__main__":
    main()
