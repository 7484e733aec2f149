"""Statistics of a demo set, from its QC logs: per task the expert's success, R_max median and
95th percentile, episode lengths, time per demo, rejection reasons, how episodes recorded again
agree with their first verdict, and the R_max histogram. The command is
``python -m mani_skill_softvt.demos stats`` (:mod:`mani_skill_softvt.cli.demos`)."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..data.demo_set import DemoSet, latest_verdicts
from ..data.trajectory import check_h5
from ..fileio import atomic_write, atomic_write_json
from ..tasks.suites import NUM_TASKS


def rerecord_agreement(qc_lines: list[dict]) -> dict:
    """How the episodes a QC log holds twice agree with their first verdict. A fresh checkout
    records again the accepted seeds its committed log lists (another machine, as a rule), and
    appends the new verdict: on another machine the same episode keeps its outcome but not its
    bits. Counts the repeats, those with the first verdict and step count, those whose R_max is the
    same bit for bit, those that diverged (NaN R_max) in one run only, and the largest finite R_max
    difference with its seed (None if every one is the same). Two NaNs (diverged twice) are the same;
    one NaN is counted on its own, since no difference measures it (and JSON has no infinity)."""
    first, agree = {}, {"repeats": 0, "same_verdict": 0, "same_steps": 0, "r_max_equal": 0, "r_max_nan_once": 0,
                        "r_max_largest_difference": 0.0, "r_max_largest_difference_seed": None}
    for line in qc_lines:
        then = first.setdefault(line["seed"], line)
        if then is line:
            continue
        agree["repeats"] += 1
        agree["same_verdict"] += line["accepted"] == then["accepted"]
        agree["same_steps"] += line["steps"] == then["steps"]
        if line.get("r_max") is None or then.get("r_max") is None:
            continue
        diverged = math.isnan(line["r_max"]), math.isnan(then["r_max"])
        if any(diverged):
            agree["r_max_equal" if all(diverged) else "r_max_nan_once"] += 1
            continue
        difference = abs(line["r_max"] - then["r_max"])
        agree["r_max_equal"] += difference == 0.0
        if difference > agree["r_max_largest_difference"]:
            agree["r_max_largest_difference"], agree["r_max_largest_difference_seed"] = difference, line["seed"]
    return agree


def _pooled_agreement(rows: list[dict]) -> dict:
    """:func:`rerecord_agreement` over every task: the counts summed, the largest difference kept."""
    pooled = {k: sum(r["rerecorded"].get(k, 0) for r in rows)
              for k in ("repeats", "same_verdict", "same_steps", "r_max_equal", "r_max_nan_once")}
    worst = max(rows, key=lambda r: r["rerecorded"]["r_max_largest_difference"])["rerecorded"]
    return {**pooled, "r_max_largest_difference": worst["r_max_largest_difference"],
            "r_max_largest_difference_seed": worst["r_max_largest_difference_seed"]}


def stats(suite: str, out: Path) -> dict:
    """Per task: expert success (accepted / generated), R_max median and 95th percentile, episode
    lengths, wall seconds per demo, rejection reasons, and how episodes recorded again agree with
    their first verdict (:func:`rerecord_agreement`). Writes ``stats.json`` and ``r_max_hist.png``
    next to the suite's demos; raises FileNotFoundError when there are none."""
    demo_set = DemoSet(out, suite)
    rows, all_r, corrupt = [], [], []
    for t in range(NUM_TASKS):
        log = demo_set.read_qc(t)
        qc = latest_verdicts(log)
        if not qc:
            continue
        # From the QC log, so an interrupted run (episodes recorded, not yet merged) counts too.
        eps = [q for q in qc if q["accepted"]]
        r = [e["r_max"] for e in eps]
        all_r += r
        walls = [q["wall_s"] for q in qc if "wall_s" in q]
        corrupt += _unreadable_files(demo_set, t, eps)
        rows.append({"task_id": t, "generated": len(qc), "accepted": len(eps), "success_rate": len(eps) / len(qc),
                     **_r_max_summary(r),
                     "length_mean": float(np.mean([e["steps"] for e in eps])) if eps else None,
                     "recorded_here": sum(demo_set.episode_file(t, e["seed"]).exists() for e in eps),
                     "seconds_per_demo": float(np.mean(walls)) if walls else None,
                     "rejected": dict(Counter(p for q in qc for p in q.get("problems", []))),
                     "rerecorded": rerecord_agreement(log)})
    if not rows:
        raise FileNotFoundError(f"no demos of suite '{suite}' under {out}; run "
                                f"'python -m mani_skill_softvt.demos generate --suite {suite} --out {out}' first")
    summary = {"suite": suite, "tasks": rows,
               "generated": sum(r["generated"] for r in rows), "accepted": sum(r["accepted"] for r in rows),
               **_r_max_summary(all_r), "rerecorded": _pooled_agreement(rows), "unreadable_files": corrupt}
    atomic_write_json(demo_set.stats, summary)
    if all_r:
        fig = Figure(figsize=(5, 3))
        ax = fig.subplots()
        ax.hist(all_r, bins=20, range=(0, 1.2), color="tab:blue")
        ax.axvline(1.0, color="k", ls="--")
        ax.set_xlabel("R_max per demo")
        ax.set_ylabel("demos")
        ax.set_title(f"{suite}: {len(all_r)} accepted demos")
        fig.tight_layout()
        atomic_write(demo_set.r_max_histogram, lambda p: fig.savefig(p, dpi=120))
    return summary


def _unreadable_files(demo_set: DemoSet, task_id: int, accepted: list[dict]) -> list[str]:
    """Why each of the task's demo files that should be readable is not: the accepted episodes and
    the merged trajectory are read in full (states only, small); renderings (images, large) are
    opened, which is where a truncated HDF5 file fails."""
    # An accepted episode that is not here is not unreadable: a set screened elsewhere
    # (generate --screen-only) lists it; `recorded_here` in the stats counts those that are.
    files = [p for p in (demo_set.episode_file(task_id, q["seed"]) for q in accepted) if p.exists()]
    files += [p for p in (demo_set.trajectory(task_id),) if p.exists()]
    problems = [check_h5(p) for p in files] + [check_h5(p, read=False) for p in demo_set.renderings(task_id)]
    return [p for p in problems if p]


def _r_max_summary(r_max: list[float]) -> dict:
    """Median, 95th percentile (None without demos) and count above 1 of per-demo R_max values."""
    return {"r_max_median": float(np.median(r_max)) if r_max else None,
            "r_max_p95": float(np.percentile(r_max, 95)) if r_max else None,
            "r_max_above_1": int(sum(x > 1 for x in r_max))}


def format_stats(summary: dict) -> str:
    """The stats of :func:`stats` as a plain-text table, one row per task and a total."""
    def num(x, fmt):
        return "-" if x is None else format(x, fmt)

    head = f"{'task':>4}  {'success':>9}  {'R_max med':>9}  {'R_max p95':>9}  {'>1':>3}  {'steps':>6}  {'s/demo':>6}  rejected"
    lines = [f"{summary['suite']}: expert demos", head, "-" * len(head)]
    for r in summary["tasks"]:
        rej = ", ".join(f"{k} x{v}" for k, v in r["rejected"].items())
        lines.append(f"{r['task_id']:>4}  {r['accepted']:>4}/{r['generated']:<4}  {num(r['r_max_median'], '9.3f')}  "
                     f"{num(r['r_max_p95'], '9.3f')}  {r['r_max_above_1']:>3}  {num(r['length_mean'], '6.1f')}  "
                     f"{num(r['seconds_per_demo'], '6.1f')}  {rej}")
    lines.append("-" * len(head))
    lines.append(f"{'all':>4}  {summary['accepted']:>4}/{summary['generated']:<4}  {num(summary['r_max_median'], '9.3f')}  "
                 f"{num(summary['r_max_p95'], '9.3f')}  {summary['r_max_above_1']:>3}")
    here = sum(r.get("recorded_here", r["accepted"]) for r in summary["tasks"])
    if here < summary["accepted"]:
        lines.append(f"on this machine: {here} of the {summary['accepted']} accepted episodes (the others screened "
                     f"elsewhere; generate without --screen-only records them, the same bits)")
    again = summary.get("rerecorded") or {}
    if again.get("repeats"):
        n, seed = again["repeats"], again["r_max_largest_difference_seed"]
        lines.append(f"recorded again: {n}; first verdict kept {again['same_verdict']}/{n}, step count "
                     f"{again['same_steps']}/{n}, R_max the same bits {again['r_max_equal']}/{n}"
                     + ("" if seed is None else f", largest R_max difference "
                        f"{again['r_max_largest_difference']:.2g} (seed {seed})")
                     + (f", diverged (NaN R_max) in one run only {again['r_max_nan_once']}"
                        if again.get("r_max_nan_once") else ""))
    return "\n".join(lines)
