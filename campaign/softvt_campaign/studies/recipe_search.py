"""The recipe search of the CPU baselines (campaign step 2): named recipes, trained on the same
demos with held-out demos set aside, ranked by their held-out open-loop error.

    python -m softvt_campaign.studies.recipe_search --variant vo-c --recipes base long --budget-min 120
    python -m softvt_campaign.studies.recipe_search --variant vo-c --recipes long --set batch_size=64
    python -m softvt_campaign.studies.recipe_search --variant vo-c --recipes long --closed-loop 10 --steps 6000 12000
    python -m softvt_campaign.studies.recipe_search --variant vo-c --table       # the results so far

A recipe is a set of :class:`~softvt_campaign.baselines.config.DPConfig` overrides on the cpu
preset (:data:`~.config.RECIPES`), plus any ``--set key=value`` (the run is then named
``<variant>-<recipe>+key=value``), always with ``heldout_per_task`` = ``--heldout`` (demos of each task
never trained on: those after ``--demos-per-task``, which stay the same as the set grows). Each run trains under ``--runs`` (outside the checkout: checkpoints and
the prepared data are large), resuming where it stopped, until it ends or the time budget runs
out; it keeps a snapshot policy every ``--snapshot-every`` steps. Every snapshot's open-loop
error (:mod:`.openloop`) and training time become a line of ``campaign-data/search/<variant>.jsonl``
(committed: the table survives the machine), so each recipe yields a curve of error against
training time. The runs share one prepared-data cache (``<runs>/data_cache``): recipes that read
the demos the same way read one copy. A recipe that differs from one trained earlier in the same
command only in how the network is sampled (:data:`~.config.INFERENCE_FIELDS`: ``exec4`` of
``long``) is not trained again: its snapshots are the other's weights with its own config.

``--closed-loop N`` trains nothing: it evaluates the runs' snapshots (those of ``--steps``, default
all) on the ID protocol, N episodes per task, with ``--workers`` processes, into
``campaign-data/search/closed_loop/<run>/object_soft_id_<snapshot>.jsonl`` (committed, resumable:
``evaluate``'s records). It can run beside a training run. The table then shows TSR and DSR with
their Wilson intervals beside the open-loop error, and ``campaign-data/search/<variant>.png`` plots
both against training time (the chosen recipe's curve of TSR against training time).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import time
from pathlib import Path

from matplotlib.figure import Figure
from tqdm import tqdm

from ..baselines.agent import read_policy_file, resolve_policy_file
from ..baselines.bf16 import choose_products
from ..baselines.config import RECIPES, VARIANTS, parse_override, recipe_config, training_identity
from ..baselines.train import POLICY, save, snapshot_path, train
from mani_skill_softvt.evaluation.metrics import percent_ci, summarize
from mani_skill_softvt.evaluation.protocols import episode_key
from mani_skill_softvt.evaluation.records import read_records
from mani_skill_softvt.evaluation.run import RunConfig
from mani_skill_softvt.evaluation.runner import evaluate
from mani_skill_softvt.fileio import append_jsonl, atomic_write, read_jsonl
from mani_skill_softvt.paths import DEMOS_DIR, REPO_DIR
from .openloop import load_run_windows, openloop

# Checkpoints and prepared data are large: outside the repository's tracked files (the campaign
# keeps them beside its demos, SOFTVT_RUNS_DIR); the results table is small and committed.
RUNS_DIR = Path(os.environ.get("SOFTVT_RUNS_DIR", REPO_DIR / "outputs" / "recipe_search"))
RESULTS_DIR = REPO_DIR / "campaign-data" / "search"
HELDOUT = 10  # demos per task set aside (the last ones), for every recipe alike
SNAPSHOT_EVERY = 1500


SEARCH_FIELDS = ("threads", "demos_per_task", "heldout_per_task")  # the search's own flags set these, not --set


def search_config(variant: str, recipe: str, heldout: int = HELDOUT, overrides: dict | None = None, **extra):
    """The recipe's config (:func:`~.config.recipe_config`) with ``overrides`` (``--set``) and the
    held-out split; ``extra`` (threads, demos per task) does not name the run."""
    return recipe_config(variant, recipe, overrides, heldout_per_task=heldout, **extra)


def recipe_label(recipe: str, overrides: dict | None = None) -> str:
    """A recipe with its ``--set`` overrides, as runs and results name it: the parsed values in key
    order (``long+batch_size=64+camera_size=96,96``), so one config has one name."""
    text = lambda v: ",".join(map(str, v)) if isinstance(v, tuple) else "none" if v is None else str(v)
    label = "+".join([recipe, *(f"{k}={text(v)}" for k, v in sorted((overrides or {}).items()))])
    if "/" in label or label.startswith("."):
        raise ValueError(f"run name {label!r}: overrides name a directory, so they may not hold '/' or begin with '.'")
    return label


def run_snapshots(run: Path) -> list[Path]:
    """The finished snapshot policies of a run, by step (an atomic write's temporary file, a dot
    file, is not one)."""
    return sorted((p for p in (Path(run) / "snapshots").glob("*.pt") if not p.name.startswith(".")),
                  key=snapshot_step)


def results_path(variant: str, results_dir: Path = RESULTS_DIR) -> Path:
    return Path(results_dir) / f"{variant}.jsonl"


def measured(variant: str, results_dir: Path = RESULTS_DIR) -> dict[tuple[str, int], dict]:
    """The open-loop results logged so far, by (run, step): a run is a recipe's config on its demos."""
    return {(r["run"], r["step"]): r for r in read_jsonl(results_path(variant, results_dir))}


def run_id(cfg, data_key: str) -> str:
    """A run's identity in the results: its config and the episodes it trained on (another
    --demos-per-task, --heldout or an edited recipe is another run)."""
    return hashlib.sha256(json.dumps([cfg.to_dict(), data_key], default=list).encode()).hexdigest()[:12]


def snapshot_step(path: Path) -> int:
    """The step of a snapshot from its name (``<run>_step001500.pt``)."""
    return int(Path(path).stem.rsplit("_step", 1)[1])


def measure_snapshots(variant: str, recipe: str, run: Path, cfg, demos_root: Path, results_dir: Path, windows: int,
                      threads: int, cache: Path | None = None) -> list[dict]:
    """Log the open-loop error of every snapshot of the run of ``cfg`` in ``run`` not yet logged;
    the new lines. The run's data is read once for all its snapshots."""
    done = measured(variant, results_dir)
    todo = run_snapshots(run)
    if not todo:
        return []
    identity = run_id(cfg, read_policy_file(todo[0])[1].get("data_key", ""))
    todo = [s for s in todo if (identity, snapshot_step(s)) not in done]
    data = load_run_windows(cfg, run, demos_root, cache) if todo else None
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


def derive_snapshots(source: Path, run: Path, cfg) -> int:
    """Give ``run`` the snapshots (and ``policy.pt``) of ``source``, a run whose config differs from
    ``cfg`` only in :data:`~.config.INFERENCE_FIELDS`: the same weights, sampled as ``cfg`` says.
    Training it would give those weights bit for bit; this costs seconds. Returns how many files
    were written (those already there are kept)."""
    snaps = run_snapshots(source)
    if snaps and training_identity(read_policy_file(snaps[0])[0]) != training_identity(cfg):
        raise ValueError(f"{source} trains otherwise than {run} would; it cannot stand in for it")
    pairs = [(snap, snapshot_path(run, snapshot_step(snap))) for snap in snaps]
    pairs += [(source / POLICY, run / POLICY)] if (source / POLICY).exists() else []
    written = 0
    for src, dest in pairs:
        if not dest.exists():
            ckpt = read_policy_file(src)[1]
            save(dest, {**ckpt, "config": cfg.to_dict(), "derived_from": str(src)})
            written += 1
    return written


def closed_loop_dir(results_dir: Path, run: str) -> Path:
    """Where the closed-loop records of run ``run`` (its :func:`run_id`) go."""
    return Path(results_dir) / "closed_loop" / run


def evaluate_snapshots(run: Path, per_task: int, steps: list[int] | None, workers: int, results_dir: Path,
                       suite: str = "object_soft", tasks: list[int] | None = None) -> dict[tuple[str, int], dict]:
    """Evaluate the run's snapshots (of ``steps``, default all) on the ID protocol, ``per_task``
    episodes of each of ``tasks`` (default all), resuming; the summaries of every evaluated
    snapshot (:func:`closed_loop_summaries`)."""
    every = run_snapshots(run)
    if not every:
        raise ValueError(f"{run} has no snapshots to evaluate; train it first (the same command without --closed-loop)")
    snaps = [s for s in every if steps is None or snapshot_step(s) in steps]
    missing = sorted(set(steps or ()) - {snapshot_step(s) for s in snaps})
    if missing:
        raise ValueError(f"{run}: no snapshots of steps {missing} (it has {[snapshot_step(s) for s in every]}); "
                         "train further, or pick others with --steps")
    for snap in snaps:
        source, cfg, ckpt = resolve_policy_file(str(snap.resolve()))  # one read: config, modes, hash
        run = RunConfig.resolve(source, suite=suite, tasks=tasks if tasks is not None else "all",
                                episodes_per_task=per_task)
        out = closed_loop_dir(results_dir, run_id(cfg, ckpt.get("data_key", ""))) / f"{suite}_id_{snap.stem}.jsonl"
        with tqdm(total=len(run.episodes()), desc=f"closed loop {snap.stem}", unit="episode") as bar:
            evaluate(run, out, workers=workers, progress=bar.update)
    return closed_loop_summaries(results_dir)


def closed_loop_summaries(results_dir: Path = RESULTS_DIR) -> dict[tuple[str, int], dict]:
    """TSR and DSR (with Wilson intervals) of every evaluated snapshot, by (run, step); an episode
    evaluated twice (the snapshot file moved, so another policy path) counts once, its last record."""
    out = {}
    for path in sorted(Path(results_dir).glob("closed_loop/*/*.jsonl")):
        records = list({episode_key(r): r for r in read_records(path)}.values())
        if records:
            summary = summarize(records)
            summary["per_task"] = len(records) // len({r["task_id"] for r in records})
            out[(path.parent.name, snapshot_step(path.with_suffix(".pt")))] = summary
    return out


def format_table(variant: str, results_dir: Path = RESULTS_DIR, closed: dict | None = None) -> str:
    """The logged results, one row per (recipe, step), by recipe then step; closed-loop TSR and
    DSR (95 % Wilson intervals) where the snapshot was evaluated (``closed``: the
    :func:`closed_loop_summaries`, when the caller has them)."""
    rows = sorted(measured(variant, results_dir).values(), key=lambda r: (r["recipe"], r["run"], r["step"]))
    closed = closed_loop_summaries(results_dir) if closed is None else closed
    head = ("| recipe (run) | demos trained / held out | step | training min | held-out pos mm | 1st action mm | rot deg "
            "| gripper | training pos mm | closed-loop episodes | TSR % [95% CI] | DSR % [95% CI] |\n|---|---|---|---|---|---|---|---|---|---|---|---|")
    title = (f"{variant}: open-loop error of the executed actions at every replanning step; closed-loop TSR and DSR "
             "on the ID protocol")
    lines = [title, "", head]
    for r in rows:
        h, t = r["heldout"], r["training"]
        c = closed.get((r["run"], r["step"]))
        loop = f"{c['episodes']} | {percent_ci(c['tsr'], c['tsr_ci95'], 0)} | {percent_ci(c['dsr'], c['dsr_ci95'], 0)}" if c else " | | "
        lines.append(f"| {r['recipe']} ({r['run'][:6]}) | {r['episodes_trained']} / {r['episodes_heldout']} | {r['step']} | {r['train_wall_s'] / 60:.0f} | {h['position_mm_mean']:.1f} | "
                     f"{h['position_mm_first_action']:.1f} | {h['rotation_deg_mean']:.2f} | {h['gripper_mean']:.3f} | "
                     f"{t['position_mm_mean']:.1f} | {loop} |")
    return "\n".join(lines)


def plot_curves(variant: str, results_dir: Path = RESULTS_DIR, closed: dict | None = None) -> Path | None:
    """``<results>/<variant>.png``: held-out open-loop error and closed-loop TSR against training
    time, one line per run; None when nothing is logged."""
    rows = list(measured(variant, results_dir).values())
    if not rows:
        return None

    closed = closed_loop_summaries(results_dir) if closed is None else closed
    fig = Figure(figsize=(11, 4))
    (ax_err, ax_tsr) = fig.subplots(1, 2)
    for i, run in enumerate(sorted({r["run"] for r in rows})):
        mine = sorted((r for r in rows if r["run"] == run), key=lambda r: r["step"])
        label, color = f"{mine[0]['recipe']} ({run[:6]})", f"C{i % 10}"  # one colour per run in both panels
        minutes = [r["train_wall_s"] / 60 for r in mine]
        ax_err.plot(minutes, [r["heldout"]["position_mm_mean"] for r in mine], "o-", label=label, color=color)
        loop = [(m, closed[(run, r["step"])]) for m, r in zip(minutes, mine) if (run, r["step"]) in closed]
        if loop:
            x = [m for m, _ in loop]
            tsr = [100 * c["tsr"] for _, c in loop]
            lo = [100 * c["tsr_ci95"][0] for _, c in loop]
            hi = [100 * c["tsr_ci95"][1] for _, c in loop]
            ax_tsr.errorbar(x, tsr, yerr=[[a - b for a, b in zip(tsr, lo)], [b - a for a, b in zip(tsr, hi)]],
                            fmt="o-", capsize=3, label=label, color=color)
    ax_err.set(xlabel="training time (min, one core)", ylabel="held-out TCP position error (mm)",
               title=f"{variant}: open loop")
    ax_tsr.set(xlabel="training time (min, one core)", ylabel="TSR (%), 95 % Wilson interval", ylim=(0, 100),
               xlim=(0, max(ax_err.get_xlim()[1], 1.0)), title=f"{variant}: closed loop, ID protocol")  # the same time axis
    for ax in (ax_err, ax_tsr):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.tight_layout()
    path = Path(results_dir) / f"{variant}.png"
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))
    return path


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(prog="python -m softvt_campaign.studies.recipe_search", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variant", default="vo-c", choices=VARIANTS)
    ap.add_argument("--recipes", nargs="+", default=["base"], help=f"of {sorted(RECIPES)}, trained in this order")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                    help="overrides on top of every recipe (the runs are named <variant>-<recipe>+KEY=VALUE)")
    ap.add_argument("--budget-min", type=float, default=None, help="stop training after this many minutes (resumable)")
    ap.add_argument("--heldout", type=int, default=HELDOUT,
                    help="demos per task set aside: the ones after --demos-per-task (else the last ones)")
    ap.add_argument("--demos-per-task", type=int, default=None, help="demos per task trained on (default: all others)")
    ap.add_argument("--snapshot-every", type=int, default=SNAPSHOT_EVERY)
    ap.add_argument("--windows", type=int, default=500, help="replanning steps measured per set and snapshot")
    ap.add_argument("--threads", type=int, default=1, help="torch threads for training and measuring")
    ap.add_argument("--closed-loop", type=int, default=None, metavar="N",
                    help="train nothing: evaluate the recipes' snapshots on the ID protocol, N episodes per task")
    ap.add_argument("--steps", type=int, nargs="+", default=None, help="with --closed-loop: these snapshots only")
    ap.add_argument("--workers", type=int, default=1, help="with --closed-loop: evaluation processes")
    ap.add_argument("--demos", type=Path, default=DEMOS_DIR)
    ap.add_argument("--runs", type=Path, default=RUNS_DIR, help="run directories (checkpoints, prepared data)")
    ap.add_argument("--results", type=Path, default=RESULTS_DIR, help="where the results table is logged")
    ap.add_argument("--table", action="store_true", help="print the results logged so far, redraw the plot, and exit")
    args = ap.parse_args(argv)
    if args.table:
        return _report(args.variant, args.results)
    unknown = sorted(set(args.recipes) - set(RECIPES))
    if unknown:
        ap.error(f"unknown recipes {unknown}; the recipes are {sorted(RECIPES)}")
    if args.steps is not None and args.closed_loop is None:
        ap.error("--steps picks the snapshots --closed-loop evaluates; give --closed-loop N too")
    try:  # every run's config is checked before the first one trains for hours
        overrides = dict(parse_override(s) for s in args.set)
        own = sorted(set(overrides) & set(SEARCH_FIELDS))
        if own:
            raise ValueError(f"--set {own}: the search sets these with its own flags (--threads, --demos-per-task, "
                             "--heldout)")
        configs = {r: search_config(args.variant, r, args.heldout, overrides, threads=args.threads,
                                    demos_per_task=args.demos_per_task) for r in args.recipes}
        labels = {r: recipe_label(r, overrides) for r in args.recipes}
    except ValueError as e:
        ap.error(str(e))
    runs = {r: args.runs / args.variant / f"{args.variant}-{labels[r]}" for r in args.recipes}
    if args.closed_loop is not None:
        if args.closed_loop < 1 or args.workers < 1:
            ap.error("--closed-loop and --workers must be >= 1")
        for recipe in args.recipes:
            try:
                evaluate_snapshots(runs[recipe], args.closed_loop, args.steps, args.workers, args.results)
            except (FileNotFoundError, ValueError) as e:
                ap.error(str(e))
        return _report(args.variant, args.results)
    cache = args.runs / "data_cache"  # shared: recipes that read the demos alike read one copy
    deadline = None if args.budget_min is None else time.monotonic() + 60 * args.budget_min
    trained: dict[str, Path] = {}  # training_identity -> the run of this invocation that trains so
    for recipe in args.recipes:
        if deadline is not None and time.monotonic() >= deadline:
            print(f"the time budget ran out before {recipe}; run the same command again to continue")
            break
        label, run = labels[recipe], runs[recipe]  # its records and snapshots say both
        source = trained.get(training_identity(configs[recipe]))
        if source is not None:  # the same training, sampled otherwise (exec4 of long): no second run
            derive_snapshots(source, run, configs[recipe])
            policy = run / "policy.pt"
            print(f"{label}: the weights of {source.name} (the recipes differ in how they sample only)")
        else:
            # float32 products where the CPU lacks bfloat16 instructions (no bfloat16 kernel to release);
            # elsewhere the native kernels, under this process's numerics as before.
            products = choose_products("auto", configs[recipe].precision) or "native"
            policy = train(configs[recipe], args.demos, run, deadline=deadline, snapshot_every=args.snapshot_every,
                           cache=cache, bf16_products=products)
            trained[training_identity(configs[recipe])] = run
        for line in measure_snapshots(args.variant, label, run, configs[recipe], args.demos, args.results, args.windows,
                                      args.threads, cache):
            print(f"{label} step {line['step']}: held-out {line['heldout']['position_mm_mean']:.1f} mm, "
                  f"training {line['training']['position_mm_mean']:.1f} mm")
        if not policy.exists():
            print(f"{label}: the time budget ran out; run the same command again to continue")
            break
    return _report(args.variant, args.results)


def _report(variant: str, results_dir: Path) -> str:
    """Print the table and redraw the curves (``<results>/<variant>.png``)."""
    closed = closed_loop_summaries(results_dir)  # every record verified once, for the table and the plot
    table = format_table(variant, results_dir, closed)
    plot_curves(variant, results_dir, closed)
    print(table)
    return table


if __name__ == "__main__":
    main()
