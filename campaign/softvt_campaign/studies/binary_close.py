"""What a binary close does to each object against its tolerance (the findings campaign's step 4).

    python -m softvt_campaign.studies.binary_close --demos /root/binary-close --seeds 10
    python -m softvt_campaign.studies.binary_close --demos campaign-data/results/binary_close   # the committed run's logs

A binary gripper action has two values: open, or close until the fingers stall against the 10 N
force limit (``pd_ee_pose_binary``, as the release's binary action). The scripted expert runs
its own plan on the first ``--seeds`` training seeds of every task with its gripper made binary
(``demos generate --control-mode pd_ee_pose_binary``, resumable: episodes already screened are
kept), and each episode's screening says whether the task succeeded, whether the object left its
tolerance (R_max > 1, a collapsed tet) and its R_max. The same seeds' continuous expert (the
committed QC logs, ``--continuous``) stands beside it, and so does the calibration sweep's own
grasp at closure 1.0 (the card's records): its peak D against tau_o, and the share of the sweep's
stable grasps' peak D below which the binary close's lies (the lowest calibration percentile
whose tau_o a binary close would stay within). Writes ``<out>/binary_close.md`` and ``.json``.

What it tells: an object that a binary close pushes past its tolerance on every seed cannot be
carried within it by any binary policy that grasps as the expert does, so a binary variant's
DSR on it is bounded by this table, however well the policy learns.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mani_skill_softvt.calibration.cards import load_calibration_card
from mani_skill_softvt.calibration.stats import by_closure, stable_grasps
from mani_skill_softvt.data.demo_set import DemoSet
from mani_skill_softvt.fileio import read_json, write_page
from mani_skill_softvt.tasks.suites import NUM_TASKS, SUITES, task_spec

# The screening's problems that concern the tolerance alone (data/trajectory.py: episode_problems);
# any other (not successful, dropped, NaN, no plan) is a failed task.
TOLERANCE_PROBLEMS = ("R_max ", "a tet collapsed")


def screened(verdict: dict) -> dict:
    """One screening record's outcomes: task success, within tolerance, both (DSR's success), R_max
    (None when not finite: a blown-up FEM)."""
    problems = verdict.get("problems", [])
    r = verdict.get("r_max")
    r = float(r) if r is not None and np.isfinite(r) else None
    success = all(p.startswith(TOLERANCE_PROBLEMS) for p in problems)
    within = r is not None and r <= 1.0 and not any(p.startswith("a tet collapsed") for p in problems)
    return {"success": success, "within": within, "dsr_success": success and within, "r_max": r}


def task_row(binary: list[dict], continuous: list[dict]) -> dict:
    """A task's binary-close outcomes on its seeds, the continuous expert's R_max on the same seeds."""
    outs = [screened(v) for v in binary]
    r = np.array([o["r_max"] for o in outs if o["r_max"] is not None], float)
    seeds = {v["seed"] for v in binary}
    same = [screened(v) for v in continuous if v["seed"] in seeds]  # every screened seed, rejected ones too
    cont = np.array([o["r_max"] for o in same if o["r_max"] is not None], float)
    return {"episodes": len(outs), "successes": sum(o["success"] for o in outs),
            "within_tolerance": sum(o["within"] for o in outs), "dsr_successes": sum(o["dsr_success"] for o in outs),
            "r_max_median": float(np.median(r)) if r.size else None,
            "r_max_range": (float(r.min()), float(r.max())) if r.size else None,
            "continuous_episodes": len(same), "continuous_successes": sum(o["success"] for o in same),
            "continuous_dsr_successes": sum(o["dsr_success"] for o in same),
            "continuous_r_max_median": float(np.median(cont)) if cont.size else None}


def sweep_at_full_close(records: list[dict], tau_o: float, peak_d: float | None) -> dict:
    """From a card's sweep records: the scripted grasp's peak D at closure 1.0 over tau_o (median of
    its repeats), and the lowest percentile (0.01 steps) of the stable grasps' peak D that reaches
    ``peak_d``: the calibration percentile whose tau_o a binary close of peak D ``peak_d`` would stay
    within (None: beyond every stable grasp of the sweep)."""
    full = [r["peak_deformation"] for r in by_closure(records).get(1.0, [])]
    _, stable = stable_grasps(records)
    peaks = np.array([r["peak_deformation"] for r in stable], float)
    covering = None
    if peak_d is not None:
        levels = np.linspace(0.0, 100.0, 10001)
        reached = np.nonzero(np.percentile(peaks, levels) >= peak_d)[0]
        covering = float(levels[reached[0]]) if reached.size else None
    return {"sweep_r_at_closure_1": float(np.median(full)) / tau_o if full else None, "covering_percentile": covering}


def analyse(binary: DemoSet, continuous: DemoSet) -> dict:
    manifest = read_json(binary.manifest) if binary.manifest.is_file() else {}
    if not (manifest.get("control_mode") or "").endswith("_binary"):
        raise ValueError(f"{binary.manifest}: not a binary-gripper generation (control mode "
                         f"{manifest.get('control_mode')!r}); run this study with --seeds N to generate one")
    rows = {}
    for t in range(NUM_TASKS):
        verdicts = binary.verdicts(t)
        if verdicts:
            asset = task_spec(binary.suite, t).asset_id
            row = task_row(verdicts, continuous.verdicts(t))
            card = load_calibration_card(asset)
            peak = None if row["r_max_median"] is None else row["r_max_median"] * card.tau_o
            rows[t] = {"asset": asset, **row, "tau_o": card.tau_o, **sweep_at_full_close(list(card.records), card.tau_o, peak)}
    if not rows:
        raise ValueError(f"{binary.dir}: no screened episodes; run this study with --seeds N to generate them")
    n = sum(r["episodes"] for r in rows.values())
    succ = sum(r["successes"] for r in rows.values())
    dsr = sum(r["dsr_successes"] for r in rows.values())
    cn = sum(r["continuous_episodes"] for r in rows.values())
    cs = sum(r["continuous_successes"] for r in rows.values())
    cd = sum(r["continuous_dsr_successes"] for r in rows.values())
    never = [f"task {t} ({r['asset']})" for t, r in rows.items() if r["successes"] and not r["dsr_successes"]]
    summary = (f"of {n} episodes, {succ} succeed and {dsr} of them within tolerance (TSR {100 * succ / n:.0f} %, DSR "
               f"{100 * dsr / n:.0f} %); tasks carried on some seed but within tolerance on none: "
               f"{', '.join(never) if never else 'none'}. The continuous expert on the same seeds: "
               f"{cs} of {cn} succeed, {cd} within tolerance.")
    return {"suite": binary.suite, "control_mode": manifest["control_mode"], "tasks": rows, "episodes": n,
            "successes": succ, "dsr_successes": dsr, "summary": summary}


def build(result: dict) -> str:
    def fmt(x, spec=".2f"):
        return "-" if x is None else format(x, spec)

    lines = [f"# A binary close against each object's tolerance ({result['suite']}, {result['control_mode']})", "",
             "The scripted expert's plan with its gripper made binary: close means drive the fingers shut until "
             "they stall against the 10 N force limit. R_max = D_max / tau_o over the episode; the continuous "
             "expert (its calibrated closure) on the same seeds beside it.", "",
             "| task (object) | episodes | task successes | within tolerance | both (DSR) | R_max median [min, max] "
             "| continuous expert: successes / DSR, R_max median | sweep grasp at closure 1.0, R "
             "| calibration percentile covering it |", "|---|---|---|---|---|---|---|---|---|"]
    for t, r in result["tasks"].items():
        rng = f" [{r['r_max_range'][0]:.2f}, {r['r_max_range'][1]:.2f}]" if r["r_max_range"] else ""
        covering = "beyond the sweep" if r["covering_percentile"] is None else f"{r['covering_percentile']:.1f}"
        lines.append(f"| {t} ({r['asset']}) | {r['episodes']} | {r['successes']} | {r['within_tolerance']} | "
                     f"{r['dsr_successes']} | {fmt(r['r_max_median'])}{rng} | {r['continuous_successes']} / "
                     f"{r['continuous_dsr_successes']} of {r['continuous_episodes']}, {fmt(r['continuous_r_max_median'])} | "
                     f"{fmt(r['sweep_r_at_closure_1'])} | {covering} |")
    lines += ["", f"In all: {result['summary']} tau_o is the 90th percentile of peak D over the calibration sweep's "
              "stable grasps (closures up to 1.0), so the sweep's own tightest grasps lie beyond it by construction "
              "(docs/calibration.md)."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m softvt_campaign.studies.binary_close", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--demos", type=Path, required=True, help="where the binary-gripper episodes go (a store of their own)")
    ap.add_argument("--suite", default="object_soft", choices=sorted(s for s, suite in SUITES.items() if not suite.rigid),
                    help="a soft suite (the rigid twins have no tolerance to leave)")
    ap.add_argument("--seeds", type=int, default=None, metavar="N",
                    help="generate (or resume) the first N training seeds of every task first")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--continuous", type=Path, default=Path("demo-data"),
                    help="demos root holding the continuous expert's QC logs (default: the checkout's demo-data/)")
    ap.add_argument("--out", type=Path, default=Path("campaign-data/results"))
    args = ap.parse_args(argv)
    if args.seeds is not None:
        from mani_skill_softvt.demonstrations.generate import generate  # the expert and its planner: only when generating
        generate(args.suite, list(range(NUM_TASKS)), args.seeds, args.demos, workers=args.workers,
                 control_mode="pd_ee_pose_binary")
    try:
        result = analyse(DemoSet(args.demos, args.suite), DemoSet(args.continuous, args.suite))
    except ValueError as e:
        ap.error(str(e))
    text = build(result)
    write_page(args.out, "binary_close", text, result)
    print(text)
    return result


if __name__ == "__main__":
    main()
