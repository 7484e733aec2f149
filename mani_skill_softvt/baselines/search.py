"""The recipe search of the CPU baselines (campaign step 2): named recipes, trained on the same
demos with held-out demos set aside, ranked by their held-out open-loop error.

    python -m mani_skill_softvt.baselines.search --variant vo-c --recipes base long --budget-min 120
    python -m mani_skill_softvt.baselines.search --variant vo-c --table       # the results so far

A recipe is a set of :class:`~mani_skill_softvt.baselines.config.DPConfig` overrides on the cpu
preset (:data:`RECIPES`), always with ``heldout_per_task`` = ``--heldout`` (demos of each task
never trained on: those after ``--demos-per-task``, which stay the same as the set grows). Each run trains under ``--runs`` (outside the checkout: checkpoints and
the prepared data are large), resuming where it stopped, until it ends or the time budget runs
out; it keeps a snapshot policy every ``--snapshot-every`` steps. Every snapshot's open-loop
error (:mod:`.openloop`) and training time become a line of ``baselines/search/<variant>.jsonl``
(committed: the table survives the machine), so each recipe yields a curve of error against
training time, and the closed-loop TSR of the chosen recipe's snapshots (``evaluate --policy
<snapshot>``) its curve of TSR against training time.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from ..fileio import append_jsonl, read_jsonl
from ..paths import DEMOS_DIR, REPO_DIR
from .config import RECIPES, VARIANTS, make_config

# Checkpoints and prepared data are large: outside the repository's tracked files (the campaign
# keeps them beside its demos, SOFTVT_RUNS_DIR); the results table is small and committed.
RUNS_DIR = Path(os.environ.get("SOFTVT_RUNS_DIR", REPO_DIR / "outputs" / "recipe_search"))
RESULTS_DIR = REPO_DIR / "baselines" / "search"
HELDOUT = 10  # demos per task set aside (the last ones), for every recipe alike
SNAPSHOT_EVERY = 1500


def recipe_config(variant: str, recipe: str, heldout: int = HELDOUT, **extra):
    """The cpu preset of ``variant`` with the recipe's overrides and the held-out split."""
    if recipe not in RECIPES:
        raise ValueError(f"recipe {recipe!r}: choose one of {sorted(RECIPES)}")
    return make_config(variant, "cpu", **{**RECIPES[recipe], "heldout_per_task": heldout, **extra})


def results_path(variant: str, results_dir: Path = RESULTS_DIR) -> Path:
    return Path(results_dir) / f"{variant}.jsonl"


def measured(variant: str, results_dir: Path = RESULTS_DIR) -> dict[tuple[str, int], dict]:
    """The open-loop results logged so far, by (run, step): a run is a recipe's config on its demos."""
    return {(r["run"], r["step"]): r for r in read_jsonl(results_path(variant, results_dir))}


def run_id(cfg, data_key: str) -> str:
    """A run's identity in the results: its config and the episodes it trained on (another
    --demos-per-task, --heldout or an edited recipe is another run)."""
    import hashlib
    import json

    return hashlib.sha256(json.dumps([cfg.to_dict(), data_key], default=list).encode()).hexdigest()[:12]


def snapshot_step(path: Path) -> int:
    """The step of a snapshot from its name (``<run>_step001500.pt``)."""
    return int(Path(path).stem.rsplit("_step", 1)[1])


def measure_snapshots(variant: str, recipe: str, run: Path, cfg, demos_root: Path, results_dir: Path, windows: int,
                      threads: int) -> list[dict]:
    """Log the open-loop error of every snapshot of the run of ``cfg`` in ``run`` not yet logged;
    the new lines. The run's data is read once for all its snapshots."""
    from .openloop import load_run_windows, openloop
    from .train import CHECKPOINT, load_checkpoint

    done = measured(variant, results_dir)
    todo = sorted((run / "snapshots").glob("*.pt"), key=snapshot_step)
    if not todo:
        return []
    identity = run_id(cfg, load_checkpoint(run / CHECKPOINT).get("data_key", ""))
    todo = [s for s in todo if (identity, snapshot_step(s)) not in done]
    data = load_run_windows(cfg, run, demos_root) if todo else None
    new = []
    for snap in todo:
        result = openloop(snap, demos_root, windows, threads, progress=False, write=False, windows=data)
        line = {"run": identity, "recipe": recipe, "config": result["config"],
                "step": snapshot_step(snap), "train_wall_s": round(float(result["train_wall_s"] or 0.0), 1),
                "episodes_trained": result["episodes_trained"], "episodes_heldout": result["episodes_heldout"],
                "heldout": result["heldout"], "training": result["training"], "policy": snap.name}
        append_jsonl(results_path(variant, results_dir), line)
        new.append(line)
    return new


def format_table(variant: str, results_dir: Path = RESULTS_DIR) -> str:
    """The logged results, one row per (recipe, step), by recipe then step."""
    rows = sorted(measured(variant, results_dir).values(), key=lambda r: (r["recipe"], r["run"], r["step"]))
    head = ("| recipe (run) | demos trained / held out | step | training min | held-out pos mm | 1st action mm | rot deg "
            "| gripper | training pos mm |\n|---|---|---|---|---|---|---|---|---|")
    lines = [f"{variant}: open-loop error of the executed actions at every replanning step", "", head]
    for r in rows:
        h, t = r["heldout"], r["training"]
        lines.append(f"| {r['recipe']} ({r['run'][:6]}) | {r['episodes_trained']} / {r['episodes_heldout']} | {r['step']} | {r['train_wall_s'] / 60:.0f} | {h['position_mm_mean']:.1f} | "
                     f"{h['position_mm_first_action']:.1f} | {h['rotation_deg_mean']:.2f} | {h['gripper_mean']:.3f} | "
                     f"{t['position_mm_mean']:.1f} |")
    return "\n".join(lines)


def main(argv=None) -> str:
    from .train import train

    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.baselines.search", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variant", default="vo-c", choices=VARIANTS)
    ap.add_argument("--recipes", nargs="+", default=["base"], help=f"of {sorted(RECIPES)}, trained in this order")
    ap.add_argument("--budget-min", type=float, default=None, help="stop training after this many minutes (resumable)")
    ap.add_argument("--heldout", type=int, default=HELDOUT,
                    help="demos per task set aside: the ones after --demos-per-task (else the last ones)")
    ap.add_argument("--demos-per-task", type=int, default=None, help="demos per task trained on (default: all others)")
    ap.add_argument("--snapshot-every", type=int, default=SNAPSHOT_EVERY)
    ap.add_argument("--windows", type=int, default=500, help="replanning steps measured per set and snapshot")
    ap.add_argument("--threads", type=int, default=1, help="torch threads for training and measuring")
    ap.add_argument("--demos", type=Path, default=DEMOS_DIR)
    ap.add_argument("--runs", type=Path, default=RUNS_DIR, help="run directories (checkpoints, prepared data)")
    ap.add_argument("--results", type=Path, default=RESULTS_DIR, help="where the results table is logged")
    ap.add_argument("--table", action="store_true", help="print the results logged so far and exit")
    args = ap.parse_args(argv)
    if args.table:
        table = format_table(args.variant, args.results)
        print(table)
        return table
    unknown = sorted(set(args.recipes) - set(RECIPES))
    if unknown:
        ap.error(f"unknown recipes {unknown}; the recipes are {sorted(RECIPES)}")
    deadline = None if args.budget_min is None else time.monotonic() + 60 * args.budget_min
    for recipe in args.recipes:
        if deadline is not None and time.monotonic() >= deadline:
            print(f"the time budget ran out before {recipe}; run the same command again to continue")
            break
        cfg = recipe_config(args.variant, recipe, args.heldout, threads=args.threads, demos_per_task=args.demos_per_task)
        run = args.runs / args.variant / f"{args.variant}-{recipe}"  # its records and snapshots say both
        policy = train(cfg, args.demos, run, deadline=deadline, snapshot_every=args.snapshot_every)
        for line in measure_snapshots(args.variant, recipe, run, cfg, args.demos, args.results, args.windows, args.threads):
            print(f"{recipe} step {line['step']}: held-out {line['heldout']['position_mm_mean']:.1f} mm, "
                  f"training {line['training']['position_mm_mean']:.1f} mm")
        if not policy.exists():
            print(f"{recipe}: the time budget ran out; run the same command again to continue")
            break
    table = format_table(args.variant, args.results)
    print(table)
    return table


if __name__ == "__main__":
    main()
