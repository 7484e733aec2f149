"""Compare two policies (recipes) over their training seeds: the seed-level rule, on anyone's records.

    python -m mani_skill_softvt.cli.compare --a vo-c-seed0.jsonl vo-c-seed1.jsonl vo-c-seed2.jsonl \\
        --b mine-seed0.jsonl mine-seed1.jsonl mine-seed2.jsonl [--paper 10 --claim sign]

Each file holds one training seed's records of one run (``evaluate``'s JSONL, every line verified
against its hash); all are scored on the episodes they share, by default the first 25 of each task
(the pre-registered subset; ``--per-task 0`` for all). The seed variance is pooled over A and B. Printed per outcome (TSR, DSR, successes past
tolerance): every seed's score, B - A over seeds with its seed-level 95 % and 90 % intervals
(Student's t, seed variance pooled over both; docs/preregistration.md), with ``--paper`` the
verdict on that claimed difference, and rliable's mean scores with stratified-bootstrap intervals
and probability of improvement. With one seed a side there is no seed-level interval: the paired
episode-level interval is printed instead, for reading, and the verdict is unresolved.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..evaluation.metrics import paired_comparison
from ..evaluation.sidecar import crossing_note, machine, numerics, sidecar
from ..evaluation.records import read_records
from ..evaluation.seed_level import (OUTCOMES, compare_seeds, episode_key, first_per_task, outcome_of, rliable_summary,
                                    seed_scores, size_note, verdict)
from .arguments import existing_path


def load_runs(paths: list[Path]) -> list[list[dict]]:
    """The records of each file (one training seed each), verified; ValueError naming the file and line."""
    runs = []
    for p in paths:
        if not Path(p).is_file():
            raise ValueError(f"{p}: no such records file")
        recs = read_records(Path(p))
        if not recs:
            raise ValueError(f"{p}: no records")
        runs.append(recs)
    return runs


def subset(runs: list[list[dict]], per_task: int | None) -> set:
    """The episodes every run has; with ``per_task``, the first ``per_task`` of each task (by seed)."""
    return first_per_task(set.intersection(*({episode_key(r) for r in run} for run in runs)), per_task)


def report(a_runs, b_runs, episodes: set, paper: float | None, claim: str) -> str:
    lines = [f"{len(episodes)} shared episodes; A: {len(a_runs)} seed(s), B: {len(b_runs)} seed(s)"]
    for outcome in OUTCOMES:
        sa, sb = seed_scores(a_runs, outcome, episodes), seed_scores(b_runs, outcome, episodes)
        c = compare_seeds(sa, sb)
        lines.append(f"\n{outcome}: A seeds {', '.join(f'{x:.1f}' for x in sa)}; B seeds {', '.join(f'{x:.1f}' for x in sb)}")
        if c.ci95 is None:
            ea = [r for r in a_runs[0] if episode_key(r) in episodes]
            eb = [r for r in b_runs[0] if episode_key(r) in episodes]
            ep = paired_comparison([{**r, outcome: outcome_of(r, outcome)} for r in eb],
                                   [{**r, outcome: outcome_of(r, outcome)} for r in ea], outcome)
            lines.append(f"  B - A {c.difference:+.1f} points: one seed a side, no seed-level interval (unresolved); "
                         f"episode-level paired 95 % interval [{100 * ep['difference_ci95'][0]:+.1f}, "
                         f"{100 * ep['difference_ci95'][1]:+.1f}], for reading only: it leaves out the training noise")
        else:
            lines.append(f"  B - A {c.difference:+.1f} points, 95 % [{c.ci95[0]:+.1f}, {c.ci95[1]:+.1f}], "
                         f"90 % [{c.ci90[0]:+.1f}, {c.ci90[1]:+.1f}] (t, {c.df} df)")
        if paper is not None:
            v = verdict(c, paper, claim)
            note = size_note(c, paper) if claim == "size" and v == "supported" else None
            lines.append(f"  against a claimed {paper:+.1f} ({claim}): {v}{f', {note}' if note else ''}")
        r = rliable_summary([[x for x in run if episode_key(x) in episodes] for run in a_runs],
                            [[x for x in run if episode_key(x) in episodes] for run in b_runs], outcome)
        lines.append(f"  rliable: A {r['mean_a']:.1f} [{r['mean_a_ci95'][0]:.1f}, {r['mean_a_ci95'][1]:.1f}], "
                     f"B {r['mean_b']:.1f} [{r['mean_b_ci95'][0]:.1f}, {r['mean_b_ci95'][1]:.1f}] "
                     f"(stratified bootstrap); P(B beats A) {r['p_improvement']:.2f} "
                     f"[{r['p_improvement_ci95'][0]:.2f}, {r['p_improvement_ci95'][1]:.2f}]")
    return "\n".join(lines)


def machines(paths: list[Path], runs: list[list[dict]]) -> str:
    """Where each file's records ran (their stack and numerics, else the provenance sidecar beside
    them), and whether the comparison crosses machines or numerics."""
    rows = [(Path(p).name, machine(run, sidecar(p)), numerics(run, sidecar(p))) for p, run in zip(paths, runs)]
    lines = ["\nwhere the records ran:"] + [f"  {n}: {m}; numerics {x}" for n, m, x in rows]
    note = crossing_note([(m, x) for _, m, x in rows])
    if note:
        lines.append(f"  {note}")
    return "\n".join(lines)


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="the rule: docs/preregistration.md")
    ap.add_argument("--a", nargs="+", type=Path, required=True, help="recipe A: one records file per training seed")
    ap.add_argument("--b", nargs="+", type=Path, required=True, help="recipe B: one records file per training seed")
    ap.add_argument("--per-task", type=int, default=25,
                    help="score on the first N shared episodes of each task (default 25: the pre-registered subset; "
                         "0: every shared episode)")
    ap.add_argument("--paper", type=float, default=None, help="a claimed difference B - A in points, to judge")
    ap.add_argument("--claim", choices=("sign", "size", "none"), default="sign",
                    help="what --paper claims: its sign, its size, or no difference")
    args = ap.parse_args(argv)
    args.a, args.b = ([existing_path(p, flag) for p in paths] for flag, paths in (("--a", args.a), ("--b", args.b)))
    try:
        a_runs, b_runs = load_runs(args.a), load_runs(args.b)
        episodes = subset(a_runs + b_runs, args.per_task or None)
        if not episodes:
            raise ValueError("the files share no episode: compare runs of the same protocol")
        out = report(a_runs, b_runs, episodes, args.paper, args.claim) + "\n" + machines([*args.a, *args.b],
                                                                                      a_runs + b_runs)
    except ValueError as e:  # a corrupt or edited record file among them: one line, naming file and line
        ap.exit(2, f"softvt-compare: {e}\n")
    print(out)
    return out


if __name__ == "__main__":
    sys.exit(main() and 0)
