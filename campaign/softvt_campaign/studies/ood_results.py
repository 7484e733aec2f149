"""The OOD protocol's results beside the paper's (Finding 4): pooled, per condition, under stiffness shift.

    python -m softvt_campaign.studies.ood_results campaign-data/results/object_soft_ood_vo-c-cpu.jsonl \\
        campaign-data/results/object_soft_ood_vt-c-cpu.jsonl --out campaign-data/results

Each OOD records file is read with its policy's ID records (the same directory's
``<suite>_id_<policy>.jsonl``, each record verified against its hash). The OOD protocol runs the
first 10 ID initial states of every task under each of nine single-factor conditions, so every
OOD episode has an ID twin on the same seed: the comparisons against ID are paired (exact
McNemar) on those twins, beside the paper's Delta against its full ID entry. Writes
``<out>/ood.md`` and ``.json`` and ``<out>/ood_curves.png``:

- pooled over the nine conditions: TSR, DSR, TSR - DSR, with the change against ID (all 50 ID
  seeds a task, as the paper's Delta, and paired on the 10 twins);
- per condition, each variant's TSR / DSR beside the paper's Diffusion Policy table;
- under stiffness shift (E x0.5, x0.8, x1.0 = the ID twins, x2.0): TSR, DSR and R_max median
  [IQR] over all episodes, as the paper's stiffness table;
- where two variants ran the same episodes, VO against VT per condition and pooled (paired).

A run still in progress is reported as it stands: each row says how many episodes it holds.

``--twins DIR`` reads the ID twins from ``DIR/<suite>_id_<policy>.jsonl`` instead: the ID
episodes run again on the machine and stack the OOD episodes ran on. Under numerics whose bits
depend on the CPU, a learned policy's closed loop amplifies another machine's rounding into other
episodes (docs/install.md), so episodes pair best with twins from their own machine; under today's
full pins a twin is the same episode on any x86-64 machine. The report ends with where each file's
records ran, and says what its rows may compare when they cross machines or numerics.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from mani_skill_softvt.evaluation.metrics import DISTURBED_M, paired_comparison, percent, percent_ci, summarize
from mani_skill_softvt.evaluation.records import read_records
from mani_skill_softvt.evaluation.protocols import episode_key, scene_key
from mani_skill_softvt.evaluation.seed_level import clustered_difference
from mani_skill_softvt.evaluation.runner import single_run
from mani_skill_softvt.evaluation.sidecar import sidecar
from mani_skill_softvt.fileio import atomic_write, atomic_write_json
from mani_skill_softvt.tasks.suites import OOD_CONDITIONS, PhysicalFactors
from .results import provenance_lines, variant_of

# The paper's per-condition OOD table for Diffusion Policy, by soft suite (TSR, DSR %; 100 episodes each;
# its light levels x0.5, x1.33, x2.0 are ours at 67.5, 180, 270), and its pooled OOD row with the change
# against its ID entry (TSR, dTSR, DSR, dDSR).
PAPER_DP_OOD = {
    "object_soft": {
        "vo-c": {"light_67.5": (0, 0), "light_180": (37, 33), "light_270": (0, 0), "mass_x1.25": (41, 38),
                 "mass_x1.75": (40, 35), "mass_x2.5": (36, 33), "youngs_modulus_x0.5": (33, 32),
                 "youngs_modulus_x0.8": (37, 31), "youngs_modulus_x2.0": (39, 37)},
        "vt-c": {"light_67.5": (1, 1), "light_180": (36, 30), "light_270": (0, 0), "mass_x1.25": (42, 34),
                 "mass_x1.75": (43, 38), "mass_x2.5": (33, 27), "youngs_modulus_x0.5": (41, 30),
                 "youngs_modulus_x0.8": (45, 33), "youngs_modulus_x2.0": (39, 32)},
    },
    "spatial_soft": {
        "vo-c": {"light_67.5": (0, 0), "light_180": (18, 15), "light_270": (16, 9), "mass_x1.25": (5, 5),
                 "mass_x1.75": (6, 6), "mass_x2.5": (5, 5), "youngs_modulus_x0.5": (19, 13),
                 "youngs_modulus_x0.8": (17, 16), "youngs_modulus_x2.0": (13, 10)},
        "vt-c": {"light_67.5": (19, 14), "light_180": (28, 16), "light_270": (17, 13), "mass_x1.25": (18, 17),
                 "mass_x1.75": (18, 17), "mass_x2.5": (17, 15), "youngs_modulus_x0.5": (38, 23),
                 "youngs_modulus_x0.8": (34, 20), "youngs_modulus_x2.0": (37, 25)},
    },
}
PAPER_DP_POOLED_BY_SUITE = {
    "object_soft": {"vo-c": (29.2, -8.2, 26.6, -7.0), "vt-c": (31.2, -8.8, 25.0, -5.4)},
    "spatial_soft": {"vo-c": (11.0, -4.6, 8.8, -4.6), "vt-c": (25.2, -7.8, 17.8, -7.2)},
}
PAPER_DP_OBJECT_SOFT = PAPER_DP_OOD["object_soft"]  # the Object findings read these
PAPER_DP_POOLED = PAPER_DP_POOLED_BY_SUITE["object_soft"]
# The paper's stiffness table for Diffusion Policy on Object-Soft (E scale -> TSR, DSR, R_max median, IQR).
PAPER_DP_STIFFNESS = {
    "vo-c": {1.0: (42, 39, 0.63, (0.47, 0.75)), 0.5: (33, 32, 0.66, (0.06, 0.76)), 0.8: (37, 31, 0.63, (0.06, 0.79)),
             2.0: (39, 37, 0.60, (0.37, 0.71))},
    "vt-c": {1.0: (42, 30, 0.69, (0.48, 0.97)), 0.5: (41, 30, 0.76, (0.57, 0.98)), 0.8: (45, 33, 0.75, (0.54, 0.96)),
             2.0: (39, 32, 0.63, (0.41, 0.92))},
}
STIFFNESS = {0.5: "youngs_modulus_x0.5", 0.8: "youngs_modulus_x0.8", 1.0: "id", 2.0: "youngs_modulus_x2.0"}


def paper_key(variant: str) -> str:
    """``vt-c,cpu,rgb+depth`` (or ``vt-c,cpu (spatial_soft)``) -> ``vt-c``: the paper's configuration a
    variant corresponds to."""
    return variant.split(",")[0].split(" ")[0]


def id_twins(ood: list[dict], id_records: list[dict]) -> list[dict]:
    """The ID records on the OOD episodes' seeds (the protocol's shared initial states)."""
    seeds = {(r["suite"], r["task_id"], r["seed"]) for r in ood}
    return [r for r in id_records if (r["suite"], r["task_id"], r["seed"]) in seeds]


def against_twins(ood: list[dict], twins: list[dict], outcome: str) -> dict:
    """OOD against ID, paired on the seed: the ID twin of every OOD episode (condition set to match),
    with the difference clustered by initial state beside the exact McNemar (:func:`paired_clustered`)."""
    by_seed = {scene_key(r): r for r in twins}
    pairs_a, pairs_b = [], []
    for i, r in enumerate(ood):
        twin = by_seed.get(scene_key(r))
        if twin is not None:  # one ID twin serves the nine conditions: each pair gets its own key
            key = {"suite": r["suite"], "task_id": r["task_id"], "condition": f"pair{i}", "seed": r["seed"]}
            pairs_a.append({**r, **key})
            pairs_b.append({**twin, **key})
    return paired_clustered(pairs_a, pairs_b, outcome)


def paired_clustered(a: list[dict], b: list[dict], outcome: str) -> dict:
    """:func:`paired_comparison` of A against B (A - B) with ``"clustered"``: the same difference in
    points with its interval and p clustered by initial state. Pooled over the nine conditions each
    scene (and its ID twin) is counted nine times, so the McNemar p of a pooled row treats 900 pairs
    as independent where there are 100 scenes; the registered OOD inference
    (docs/preregistration.md) clusters likewise."""
    comparison = paired_comparison(a, b, outcome)
    by_b = {episode_key(r): r for r in b}
    pairs = [(r, by_b[episode_key(r)]) for r in a if episode_key(r) in by_b]
    if not pairs:
        return {**comparison, "clustered": None}
    c = clustered_difference([y[outcome] for _, y in pairs], [x[outcome] for x, _ in pairs],
                             [scene_key(x) for x, _ in pairs])
    return {**comparison, "clustered": c}


def r_max_stats(records: list[dict]) -> dict:
    """Median and interquartile range of R_max over the episodes that measured it."""
    x = np.array([r["r_max"] for r in records if r.get("r_max") is not None], float)
    if not x.size:
        return {"median": None, "iqr": None, "n": 0}
    q1, med, q3 = np.percentile(x, [25, 50, 75])
    return {"median": float(med), "iqr": (float(q1), float(q3)), "n": int(x.size)}


def analyse(runs: dict[str, tuple[list[dict], list[dict]]], twins_from: dict[str, list[dict]] | None = None) -> dict:
    """``runs``: variant -> (OOD records, ID records); ``twins_from``: variant -> the ID records to
    take the twins from (default: its ID records). Everything the report prints."""
    out = {"variants": {}, "vo_vs_vt": {}}
    for variant, (ood, id_records) in runs.items():
        twins = id_twins(ood, (twins_from or {}).get(variant, id_records))
        tasks = {(r["suite"], r["task_id"]) for r in ood}  # a run in progress: its tasks so far
        id_records = [r for r in id_records if (r["suite"], r["task_id"]) in tasks]
        by_condition = defaultdict(list)
        for r in ood:
            by_condition[r["condition"]].append(r)
        stiffness = {}
        for scale, condition in STIFFNESS.items():
            sel = twins if condition == "id" else by_condition.get(condition, [])
            if sel:
                s = summarize(sel)
                stiffness[scale] = {"episodes": s["episodes"], "tsr": s["tsr"], "dsr": s["dsr"], "r_max": r_max_stats(sel)}
        out["variants"][variant] = {
            "suite": ood[0]["suite"], "pooled": summarize(ood), "id": summarize(id_records) if id_records else None,
            "id_twins": summarize(twins) if twins else None,
            "paired_tsr": against_twins(ood, twins, "success"), "paired_dsr": against_twins(ood, twins, "dsr_success"),
            "per_condition": {c: summarize(by_condition[c]) for c in OOD_CONDITIONS if by_condition.get(c)},
            "stiffness": stiffness,
        }
    names = list(runs)
    vo = [v for v in names if paper_key(v).startswith("vo")]
    vt = [v for v in names if paper_key(v).startswith("vt")]
    for a in vo:
        for b in (b for b in vt if runs[b][0][0]["suite"] == runs[a][0][0]["suite"]):
            oa, ob = runs[a][0], runs[b][0]
            per = {}
            for c in OOD_CONDITIONS:
                ca, cb = [r for r in oa if r["condition"] == c], [r for r in ob if r["condition"] == c]
                if ca and cb:
                    per[c] = {"tsr": paired_comparison(cb, ca, "success"), "dsr": paired_comparison(cb, ca, "dsr_success")}
            out["vo_vs_vt"][f"{b} vs {a}"] = {
                "pooled_tsr": paired_clustered(ob, oa, "success"), "pooled_dsr": paired_clustered(ob, oa, "dsr_success"),
                "per_condition": per}
    return out


def legend_labels(runs: dict[str, tuple[list[dict], list[dict]]]) -> dict[str, str]:
    """Each variant's name in a plot's legend: an Object-Soft variant's name carries no suite (the
    tables' convention), so beside a Spatial-Soft run the legend adds it."""
    both_suites = len({ood[0]["suite"] for ood, _ in runs.values()}) > 1
    return {v: f"{v} ({ood[0]['suite']})" if both_suites and " (" not in v else v for v, (ood, _) in runs.items()}


def paper_condition(suite: str, variant: str, condition: str) -> str:
    """The paper's Diffusion Policy TSR / DSR for ``variant`` on ``suite`` under ``condition``, or '-'."""
    paper = PAPER_DP_OOD.get(suite, {}).get(paper_key(variant), {}).get(condition)
    return "{} / {}".format(*paper) if paper else "-"


def _points(x: float) -> str:
    return f"{100 * x:+.1f}"


def instance_lines(result: dict) -> list[str]:
    """The Spatial runs' instance counts, by condition: a success on the wrong instance is one the
    policy read the scene for, not the instruction (docs/evaluation.md)."""
    spatial = [v for v, r in result["variants"].items() if r["pooled"].get("instances")]
    if not spatial:
        return []
    lines = ["", f"## Which instance (Spatial suites): the other instance on the target / both instances disturbed "
                 f"(> {100 * DISTURBED_M:g} cm) (episodes)", "",
             "| condition | " + " | ".join(spatial) + " |", "|---" * (1 + len(spatial)) + "|"]
    for c in ("id_twins", *OOD_CONDITIONS, "pooled"):
        cells = []
        for v in spatial:
            r = result["variants"][v]
            s = r.get(c) if c in ("id_twins", "pooled") else r["per_condition"].get(c)
            i = (s or {}).get("instances")
            cells.append(f"{i['wrong_instance']} / {i['both_disturbed']} ({i['episodes']})" if i else "-")
        lines.append(f"| {c.replace('_', ' ') if c == 'id_twins' else c} | " + " | ".join(cells) + " |")
    return lines


def _clustered(comparison: dict) -> str:
    """A paired difference in points with its p: clustered by initial state where the comparison
    carries that (pooled rows), else its exact McNemar."""
    c = comparison.get("clustered")
    if c is None:
        return f"{_points(comparison['difference'])} ({comparison['p_value']:.2g})"
    if c["ci95"] is None:
        return f"{c['difference']:+.1f} (one scene: no interval)"
    return f"{c['difference']:+.1f} [{c['ci95'][0]:+.1f}, {c['ci95'][1]:+.1f}] ({c['p_value']:.2g})"


def paper_of(variant: str) -> str:
    """The paper's configuration a column's variant is set beside, with its suite when not Object-Soft."""
    suite = variant.partition(" (")[2].rstrip(")")
    return f"{paper_key(variant)} ({suite})" if suite else paper_key(variant)


def _iqr(stats: dict) -> str:
    if stats["median"] is None:
        return "-"
    return f"{stats['median']:.2f} [{stats['iqr'][0]:.2f}, {stats['iqr'][1]:.2f}]"


def build(result: dict) -> str:
    suites = sorted({r["suite"] for r in result["variants"].values()})
    titles = [s.replace("_", "-").title() for s in suites]  # object_soft -> Object-Soft, as the paper names them
    lines = [f"# OOD protocol on {' and '.join(titles)} (the paper's Finding 4)", "",
             "Nine held-out single-factor conditions x 10 tasks x 10 episodes = 900 per variant, each from an ID "
             "episode's initial state. Changes against ID: the paper's Delta is against its full ID entry (here all "
             "50 ID episodes of each task the OOD records hold, 500 when complete); *paired* is against the ID twins "
             "(the same seeds, 100 episodes when complete), exact McNemar per condition. Pooled over the nine "
             "conditions each initial state (and its ID twin) appears nine times, so a pooled row's interval and p are "
             "clustered by initial state (cluster-robust, statsmodels), not McNemar's over 900 pairs as if independent. "
             "All intervals here are over episodes of one training run: a comparison of recipes is over training seeds "
             "(seed_findings.md).", "",
             "## Pooled over the nine conditions", "",
             "| variant | OOD episodes | TSR % [95% CI] | DSR % [95% CI] | TSR - DSR | TSR vs ID | DSR vs ID "
             "| TSR vs ID twins, paired [95% CI] (p), clustered | DSR vs ID twins, paired [95% CI] (p), clustered "
             "| paper DP TSR (Delta) / DSR (Delta) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for v, r in result["variants"].items():
        p, i = r["pooled"], r["id"]
        paper = PAPER_DP_POOLED_BY_SUITE.get(r["suite"], {}).get(paper_key(v))
        paper_txt = f"{paper[0]} ({paper[1]:+}) / {paper[2]} ({paper[3]:+})" if paper else "-"
        lines.append(
            f"| {v} | {p['episodes']} | {percent_ci(p['tsr'], p['tsr_ci95'])} | {percent_ci(p['dsr'], p['dsr_ci95'])} | "
            f"{percent(p['gap'])} | {_points(p['tsr'] - i['tsr']) if i else '-'} | {_points(p['dsr'] - i['dsr']) if i else '-'} | "
            f"{_clustered(r['paired_tsr'])} | {_clustered(r['paired_dsr'])} | {paper_txt} |")
    lines += ["", "## Per condition (TSR / DSR %, episodes), beside the paper's Diffusion Policy", ""]
    variants = list(result["variants"])
    lines.append("| condition | " + " | ".join(f"{v}" for v in variants) + " | " +
                 " | ".join(f"paper DP {paper_of(v)}" for v in variants) + " |")
    lines.append("|---" * (1 + 2 * len(variants)) + "|")
    for c in OOD_CONDITIONS:
        cells = []
        for v in variants:
            s = result["variants"][v]["per_condition"].get(c)
            cells.append(f"{percent(s['tsr'], 0)} / {percent(s['dsr'], 0)} ({s['episodes']})" if s else "-")
        papers = [paper_condition(result["variants"][v]["suite"], v, c) for v in variants]
        lines.append(f"| {c} | " + " | ".join(cells) + " | " + " | ".join(papers) + " |")
    lines += instance_lines(result)
    lines += ["", "## Under stiffness shift (the paper's stiffness table; x1.0 is the ID twins)", "",
              "| E scale | variant | TSR % | DSR % | R_max median [IQR] | N | paper DP: TSR / DSR / R_max median [IQR] |",
              "|---|---|---|---|---|---|---|"]
    for scale in sorted(STIFFNESS):
        for v in variants:
            s = result["variants"][v]["stiffness"].get(scale)
            if not s:
                continue
            on_object_soft = result["variants"][v]["suite"] == "object_soft"
            paper = PAPER_DP_STIFFNESS.get(paper_key(v), {}).get(scale) if on_object_soft else None
            paper_txt = (f"{paper[0]} / {paper[1]} / {paper[2]:.2f} [{paper[3][0]:.2f}, {paper[3][1]:.2f}]"
                         if paper else "-")
            lines.append(f"| x{scale:g} | {v} | {percent(s['tsr'], 0)} | {percent(s['dsr'], 0)} | {_iqr(s['r_max'])} | "
                         f"{s['episodes']} | {paper_txt} |")
    if result["vo_vs_vt"]:
        lines += ["", "## Touch under shift: VT against VO on the same episodes (paired: pooled clustered by initial "
                  "state, per condition exact McNemar)", "",
                  "| comparison | condition | pairs | TSR, VT - VO [95% CI, pooled] (p) | DSR, VT - VO [95% CI, pooled] (p) |", "|---|---|---|---|---|"]
        for name, comp in result["vo_vs_vt"].items():
            rows = [("pooled", comp["pooled_tsr"], comp["pooled_dsr"])]
            rows += [(c, x["tsr"], x["dsr"]) for c, x in comp["per_condition"].items()]
            for c, t, d in rows:
                lines.append(f"| {name} | {c} | {t['pairs']} | {_clustered(t)} | {_clustered(d)} |")
    return "\n".join(lines) + "\n"


def plot_curves(runs: dict[str, tuple[list[dict], list[dict]]], out: Path,
                twins_from: dict[str, list[dict]] | None = None) -> None:
    """TSR and DSR against each factor's value, one line per variant, the ID twins at nominal."""
    factors = defaultdict(list)
    for name, (key, value) in OOD_CONDITIONS.items():
        factors[key].append((value, name))
    nominal = PhysicalFactors()
    fig = Figure(figsize=(4.2 * len(factors), 6))
    axes = fig.subplots(2, len(factors), squeeze=False, sharey=True)
    labels = legend_labels(runs)
    for col, (key, pts) in enumerate(factors.items()):
        for j, (variant, (ood, id_records)) in enumerate(runs.items()):
            twins = id_twins(ood, (twins_from or {}).get(variant, id_records))
            xs, tsr, dsr = [], [], []
            for value, name in sorted(pts + [(getattr(nominal, key), "id")]):
                sel = twins if name == "id" else [r for r in ood if r["condition"] == name]
                if sel:
                    s = summarize(sel)
                    xs.append(value)
                    tsr.append(100 * s["tsr"])
                    dsr.append(100 * s["dsr"])
            axes[0][col].plot(xs, tsr, "o-", color=f"C{j}", label=labels[variant])
            axes[1][col].plot(xs, dsr, "s--", color=f"C{j}", label=labels[variant])
        axes[0][col].set_title(f"TSR against {key}", fontsize=9)
        axes[1][col].set_title(f"DSR against {key}", fontsize=9)
        axes[1][col].set_xlabel(key)
        for row in (0, 1):
            axes[row][col].set_ylim(-5, 105)
            axes[row][col].set_ylabel("%")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    atomic_write(out, lambda p: fig.savefig(p, format="png", dpi=120))


def load_runs(paths: list[Path], twins: Path | None = None, twins_required: bool = True) -> tuple[dict, dict]:
    """Each OOD records file with its policy's ID records (``<suite>_id_<policy>.jsonl`` beside
    it), keyed by variant, and with ``twins`` the ID twins re-run in that directory: ``(runs,
    twins_from)`` as :func:`analyse` takes them (without ``twins_required``, a variant whose twins
    have not run yet is left out of ``twins_from``). A missing, empty or mismatched file is a
    ValueError naming it and what to do."""
    runs, twins_from = {}, {}
    for path in paths:
        if not path.is_file():
            raise ValueError(f"{path} does not exist")
        if "_ood_" not in path.name:
            raise ValueError(f"{path}: not an OOD records file (<suite>_ood_<policy>.jsonl)")
        ood = read_records(path)
        if not ood:
            raise ValueError(f"{path} holds no records")
        id_path = path.with_name(path.name.replace("_ood_", "_id_"))
        if not id_path.is_file():
            raise ValueError(f"{path}: its ID records {id_path} are missing; evaluate the policy on the ID protocol first")
        id_records = read_records(id_path)
        shas = {single_run(ood, path), single_run(id_records, id_path)}
        if len(shas) > 1:
            raise ValueError(f"{path} and {id_path} were made with different policy files (their policy_sha256 differ)")
        variant = variant_of(next((r for r in ood if r["receipt"].get("policy")), ood[0]))  # a worker_died record names none
        if ood[0]["suite"] != "object_soft":  # one report may hold both soft suites' runs of one variant
            variant = f"{variant} ({ood[0]['suite']})"
        if variant in runs:
            raise ValueError(f"two files of variant {variant}: {path} and another; report one run of each")
        runs[variant] = (ood, id_records)
        if twins is not None:
            twin_path = twins / id_path.name
            if not twin_path.is_file() and not twins_required:
                continue
            if not twin_path.is_file():
                raise ValueError(f"--twins: {twin_path} does not exist; run the ID twins there first (docs/baselines.md)")
            twin_records = read_records(twin_path)
            if single_run(twin_records, twin_path) not in shas:
                raise ValueError(f"{twin_path} was made with another policy file than {path}")
            twins_from[variant] = twin_records
    return runs, twins_from


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("ood", nargs="+", type=Path, help="OOD records files (<suite>_ood_<policy>.jsonl)")
    ap.add_argument("--out", type=Path, default=Path("campaign-data/results"))
    ap.add_argument("--twins", type=Path, default=None, metavar="DIR",
                    help="read the ID twins from DIR/<suite>_id_<policy>.jsonl (re-run on the OOD episodes' machine)")
    args = ap.parse_args(argv)
    try:
        runs, twins_from = load_runs(args.ood, args.twins)
    except ValueError as e:
        ap.error(str(e))
    result = analyse(runs, twins_from)
    files = []  # where each file read ran: the OOD runs, the ID runs they are read against, the twins
    for path, (variant, (ood, id_records)) in zip(args.ood, runs.items()):  # load_runs keeps the files' order
        id_path = path.with_name(path.name.replace("_ood_", "_id_"))
        files += [(path.name, ood, sidecar(path)), (id_path.name, id_records, sidecar(id_path))]
        if variant in twins_from:
            twin_path = args.twins / id_path.name
            files.append((f"{args.twins.name}/{id_path.name}", twins_from[variant], sidecar(twin_path)))
    text = build(result) + "\n".join(["", "## Where the records ran", *provenance_lines(files)]) + "\n"
    atomic_write(args.out / "ood.md", lambda p: p.write_text(text))
    atomic_write_json(args.out / "ood.json", result)
    plot_curves(runs, args.out / "ood_curves.png", twins_from)
    print(text)
    return result


if __name__ == "__main__":
    main()
