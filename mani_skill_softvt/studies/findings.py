"""The paper's four findings tested on the Object suites, each marked supported, contradicted or unresolved.

    python -m mani_skill_softvt.studies.findings baselines/results

Reads every record the campaign committed under the results directory (each verified against
its hash): the ID records of both Object suites (``object_soft_id_*.jsonl``,
``object_rigid_id_*.jsonl``), the OOD records (``object_soft_ood_*.jsonl``) with their ID twins
(``twins/``), and ``binary_close.json`` (:mod:`.binary_close`) where it exists. Writes
``findings.md`` and ``.json`` beside them: for each finding, the paper's numbers beside ours, the
paired exact tests on shared seeds, and a verdict per claim by the rules below. The page
docs/findings.md reads these and says why ours may differ.

The rules. Variants are compared on the same seeds (exact McNemar, two-sided). A difference
between two separately trained policies is *resolved* when p < 0.05 and it is larger than the
training-seed spread: the largest difference, in that outcome, between two training seeds of one
variant (policies ``<name>.pt`` and ``<name>-seed<N>.pt`` on the same 500 ID episodes). Until
two seeds of a variant have run, the spread is unknown and no difference between variants is
resolved. A claim of a difference is supported when ours is resolved in its direction and
contradicted when resolved against it; a claim of *no* difference is supported when ours is
not resolved with the spread known, contradicted when it is resolved. A finding is supported
when all its claims are, contradicted when any is, and unresolved otherwise. Differences within
one policy (its TSR against its DSR, its OOD episodes against their ID twins) carry no training
noise and need only p < 0.05 (or, for a count, a Wilson interval clear of zero).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from ..evaluation.metrics import paired_comparison, percent, percent_ci, summarize
from ..evaluation.protocols import seed_key
from ..evaluation.records import read_records
from ..fileio import atomic_write, atomic_write_json, read_json
from .ood_results import PAPER_DP_POOLED, analyse, load_runs
from .results import PAPER_OBJECT_SOFT, grouped, variant_name

ALPHA = 0.05
SUPPORTED, CONTRADICTED, UNRESOLVED = "supported", "contradicted", "unresolved"
SEED_SUFFIX = re.compile(r"-seed(\d+)$")  # a second training seed's policy: <name>-seed<N>.pt

# The paper's numbers each finding rests on (Object suites). Rigid-twin table: Diffusion Policy
# TSR on Object-Rigid and Object-Soft. Its sensing-control ablation is pi0.5's (TSR, DSR).
PAPER_RIGID_TWINS = {"vo-c": (40.0, 37.4), "vt-c": (35.0, 40.0)}
PAPER_ABLATION_PI05 = {"vo-b": (30.2, 27.2), "vo-c": (41.6, 38.4), "vt-b": (41.0, 28.0), "vt-c": (41.4, 35.0)}
# Finding 4's gap under shift, Diffusion Policy on Object-Soft: TSR - DSR (points) of VO-C and VT-C.
PAPER_OOD_GAP = {"vo-c": 2.6, "vt-c": 6.2}
# The variants each finding compares: VT-C is ours (tactile RGB, depth, markers).
VARIANTS = {"vo-c": "vo-c,cpu", "vt-c": "vt-c,cpu,rgb+depth", "vo-b": "vo-b,cpu", "vt-b": "vt-b,cpu,rgb+depth"}


def past_tolerance(records: list[dict]) -> list[dict]:
    """Each record with ``past_tolerance``: a task success that left the tolerance (TSR - DSR's episodes)."""
    return [{**r, "past_tolerance": bool(r["success"]) and not bool(r["dsr_success"])} for r in records]


def seed_of(tag: str) -> int:
    """The training seed a policy's file name gives: ``vo-c-cpu-seed1`` -> 1, ``vo-c-cpu`` -> 0."""
    m = SEED_SUFFIX.search(tag)
    return int(m.group(1)) if m else 0


def policies(groups: dict) -> dict[tuple[str, str], dict[int, list[dict]]]:
    """Today's ID records by (suite, variant), then by training seed: ``{("object_soft",
    "vo-c,cpu"): {0: records, 1: records}}``."""
    out: dict = {}
    for (suite, condition, label), recs in groups.items():
        if condition != "id":
            continue
        tag = label[label.index("(") + 1:label.index(")")] if "(" in label else label
        seeds = out.setdefault((suite, variant_name(label)), {})
        seed = seed_of(tag.split(" ")[0])
        if seed in seeds:
            raise ValueError(f"{suite} {variant_name(label)}: two policy files of training seed {seed} "
                             f"({tag} and another); keep one record file per seed")
        seeds[seed] = recs
    return out


def seed_spread(by_policy: dict) -> dict:
    """The training-seed spread: per outcome, the largest |difference| between two seeds of one
    variant on the same episodes, and each pair it was read from (None: no variant has two)."""
    pairs = {}
    for (suite, variant), seeds in by_policy.items():
        ordered = sorted(seeds)
        for i, a in enumerate(ordered):
            for b in ordered[i + 1:]:
                pairs[f"{suite} {variant}: seed {a} vs seed {b}"] = {
                    o: paired_comparison(past_tolerance(seeds[a]), past_tolerance(seeds[b]), o)
                    for o in ("success", "dsr_success", "past_tolerance")}
    spread = {o: (max(abs(p[o]["difference"]) for p in pairs.values()) if pairs else None)
              for o in ("success", "dsr_success", "past_tolerance")}
    return {"spread": spread, "pairs": pairs}


def resolved(comparison: dict, spread: float | None, within_policy: bool = False) -> str:
    """``"a>b"``, ``"a<b"`` or ``"none"`` (not resolved; spread known or not needed), or ``"unknown"``
    (a difference between policies while the training-seed spread is unmeasured)."""
    if not comparison["pairs"]:
        return "unknown"
    if not within_policy and spread is None:
        return "unknown"
    d = comparison["difference"]
    if comparison["p_value"] < ALPHA and (within_policy or abs(d) > spread):
        return "a>b" if d > 0 else "a<b"
    return "none"


def claim(text: str, outcome: str, expected: str) -> dict:
    """A claim's verdict: ``expected`` is the paper's direction (``a>b``, ``a<b`` or ``none``) and
    ``outcome`` ours (:func:`resolved`, or ``missing`` when the records have not run yet)."""
    if outcome in ("missing", "unknown"):
        verdict = UNRESOLVED
    elif expected == "none":
        verdict = SUPPORTED if outcome == "none" else CONTRADICTED
    elif outcome == expected:
        verdict = SUPPORTED
    elif outcome == "none":
        verdict = UNRESOLVED
    else:
        verdict = CONTRADICTED
    return {"claim": text, "ours": outcome, "paper": expected, "verdict": verdict}


def overall(claims: list[dict]) -> str:
    verdicts = {c["verdict"] for c in claims}
    if CONTRADICTED in verdicts:
        return CONTRADICTED
    return SUPPORTED if claims and verdicts == {SUPPORTED} else UNRESOLVED


def _seeds0(by_policy: dict, suite: str, key: str) -> list[dict] | None:
    """The first training seed's ID records of a variant (``vo-c`` ...) on a suite, if they ran."""
    return by_policy.get((suite, VARIANTS[key]), {}).get(0)


def _compare(a: list[dict] | None, b: list[dict] | None, outcome: str, key=None) -> dict | None:
    if a is None or b is None:
        return None
    kw = {"key": key} if key else {}
    return paired_comparison(past_tolerance(a), past_tolerance(b), outcome, **kw)


def _verdict_of(comparison: dict | None, spread: float | None, within_policy: bool = False) -> str:
    return "missing" if comparison is None else resolved(comparison, spread, within_policy)


def finding1(by_policy: dict, spread: dict) -> dict:
    """Completion-only evaluation hides violations, and they depend on the policy: every variant
    has successes past its tolerance (an exact count on the same episodes, as the paper says), and
    two variants' counts differ beyond the training noise; pairs of variants whose TSR and DSR rank
    them in opposite orders are listed."""
    rows = {f"{v} (seed {s})": summarize(recs) for (suite, v), seeds in sorted(by_policy.items())
            if suite == "object_soft" for s, recs in sorted(seeds.items())}
    claims = [claim(f"{name}: successes past tolerance (TSR - DSR) > 0",
                    "a>b" if row["task_successes"] > row["dsr_successes"] else "none", "a>b")
              for name, row in rows.items()]
    firsts = {v: seeds[0] for (suite, v), seeds in by_policy.items() if suite == "object_soft" and 0 in seeds}
    names = sorted(firsts)
    reversals, gaps = {}, {}
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            t, d, g = (_compare(firsts[a], firsts[b], o) for o in ("success", "dsr_success", "past_tolerance"))
            gaps[f"{a} vs {b}"] = g
            if t["difference"] * d["difference"] < 0:
                reversals[f"{a} vs {b}"] = {"tsr": t, "dsr": d}
    outcomes = {resolved(g, spread["past_tolerance"]) for g in gaps.values()}
    differ = ("missing" if not gaps else "a>b" if outcomes & {"a>b", "a<b"} else
              "unknown" if "unknown" in outcomes else "none")
    claims.append(claim("the count past tolerance depends on the policy (two variants differ in TSR - DSR)", differ, "a>b"))
    return {"rows": rows, "gap_differences": gaps, "claims": claims, "misrankings": reversals,
            "verdict": overall(claims)}


def finding2(by_policy: dict, spread: dict) -> dict:
    """The cost of deformability for Diffusion Policy on the Object suites: the paper's rigid and
    soft TSR are within its resolution (no cost resolved); ours paired on the shared seeds."""
    claims, pairs = [], {}
    for key in ("vo-c", "vt-c"):
        c = _compare(_seeds0(by_policy, "object_rigid", key), _seeds0(by_policy, "object_soft", key), "success", seed_key)
        pairs[key] = c
        rigid, soft = PAPER_RIGID_TWINS[key]
        claims.append(claim(f"{key}: rigid twin TSR - soft TSR not resolved (paper {rigid - soft:+.1f} points, "
                            "within its resolution)", _verdict_of(c, spread["success"]), "none"))
    return {"pairs": pairs, "claims": claims, "verdict": overall(claims)}


def finding3(by_policy: dict, spread: dict, binary_close: dict | None) -> dict:
    """Sensing against control granularity (the 2x2 ablation; the paper's is pi0.5's)."""
    soft = {k: _seeds0(by_policy, "object_soft", k) for k in ("vo-b", "vo-c", "vt-b", "vt-c")}
    rows = {k: (summarize(r) if r else None) for k, r in soft.items()}
    c_vs_b_vo = {o: _compare(soft["vo-c"], soft["vo-b"], o) for o in ("success", "dsr_success")}
    c_vs_b_vt = {o: _compare(soft["vt-c"], soft["vt-b"], o) for o in ("success", "dsr_success")}
    vt_vs_vo_c = {o: _compare(soft["vt-c"], soft["vo-c"], o) for o in ("success", "dsr_success")}
    vt_vs_vo_b = {o: _compare(soft["vt-b"], soft["vo-b"], o) for o in ("success", "dsr_success")}
    s = spread["spread"]
    claims = [
        claim("continuous control alone raises TSR (VO-C > VO-B; paper +11.4)", _verdict_of(c_vs_b_vo["success"], s["success"]), "a>b"),
        claim("touch adds no TSR on top of continuous control (VT-C = VO-C; paper -0.2)",
              _verdict_of(vt_vs_vo_c["success"], s["success"]), "none"),
        claim("continuous control raises DSR with vision only (VO-C > VO-B; paper +11.2)",
              _verdict_of(c_vs_b_vo["dsr_success"], s["dsr_success"]), "a>b"),
        claim("continuous control raises DSR with touch (VT-C > VT-B; paper +7.0)",
              _verdict_of(c_vs_b_vt["dsr_success"], s["dsr_success"]), "a>b"),
    ]
    return {"rows": rows, "continuous_vs_binary": {"vo": c_vs_b_vo, "vt": c_vs_b_vt},
            "touch_vs_vision": {"continuous": vt_vs_vo_c, "binary": vt_vs_vo_b},
            "binary_close": binary_close, "claims": claims, "verdict": overall(claims)}


def finding4(ood: dict | None, spread: dict) -> dict:
    """Touch under distribution shift: VT-C against VO-C on the same 900 OOD episodes (TSR higher
    with touch), and the TSR - DSR gap under shift wider with touch (DP on Object-Soft)."""
    s = spread["spread"]
    if ood is None:
        claims = [claim("touch raises pooled OOD TSR (VT-C > VO-C; paper +2.0)", "missing", "a>b"),
                  claim("touch widens the TSR - DSR gap under shift (paper 2.6 -> 6.2 points)", "missing", "a>b")]
        return {"claims": claims, "verdict": UNRESOLVED, "ood": None}
    runs, twins_from = ood["runs"], ood["twins_from"]
    result = analyse(runs, twins_from)
    vo = next((v for v in runs if v == VARIANTS["vo-c"]), None)
    vt = next((v for v in runs if v == VARIANTS["vt-c"]), None)
    complete = vo and vt and all(len(runs[v][0]) == 900 for v in (vo, vt))
    tsr = gap = None
    if vo and vt:
        tsr = _compare(runs[vt][0], runs[vo][0], "success")
        gap = _compare(runs[vt][0], runs[vo][0], "past_tolerance")
    claims = [
        claim("touch raises pooled OOD TSR (VT-C > VO-C; paper +2.0)",
              _verdict_of(tsr, s["success"]) if complete else "missing", "a>b"),
        claim("touch widens the TSR - DSR gap under shift (paper 2.6 -> 6.2 points)",
              _verdict_of(gap, s["past_tolerance"]) if complete else "missing", "a>b"),
    ]
    drops = {v: {"tsr": r["paired_tsr"], "dsr": r["paired_dsr"],
                 "twins": "re-run on the OOD machine" if v in twins_from else "the committed ID records"}
             for v, r in result["variants"].items()}
    return {"claims": claims, "verdict": overall(claims), "vt_vs_vo_tsr": tsr, "vt_vs_vo_gap": gap,
            "pooled": {v: r["pooled"] for v, r in result["variants"].items()}, "against_id_twins": drops,
            "complete": bool(complete)}


def machine_spread(results_dir: Path) -> dict:
    """The same policy on the same ID episodes on two machines (the committed records against the
    twins re-run beside the OOD episodes): how far the machine alone moves an outcome."""
    out = {}
    for twin_path in sorted((results_dir / "twins").glob("*_id_*.jsonl")):
        committed = results_dir / twin_path.name
        if committed.is_file():
            a, b = read_records(committed), read_records(twin_path)
            out[twin_path.stem] = {o: paired_comparison(a, b, o) for o in ("success", "dsr_success")}
    return out


def load(results_dir: Path) -> dict:
    """Everything the findings read from a results directory (see the module docstring)."""
    id_records = [r for suite in ("object_soft", "object_rigid")
                  for p in sorted(results_dir.glob(f"{suite}_id_*.jsonl")) for r in read_records(p)]
    if not id_records:
        raise ValueError(f"{results_dir}: no ID records (object_soft_id_*.jsonl); evaluate a policy first")
    ood_paths = sorted(results_dir.glob("object_soft_ood_*.jsonl"))
    twins = results_dir / "twins"
    ood = None
    if ood_paths:
        runs, twins_from = load_runs(ood_paths, twins if twins.is_dir() else None, twins_required=False)
        ood = {"runs": runs, "twins_from": twins_from}
    binary = results_dir / "binary_close.json"
    return {"groups": grouped(id_records), "ood": ood, "binary_close": read_json(binary) if binary.is_file() else None,
            "machine_spread": machine_spread(results_dir)}


def analyse_findings(data: dict) -> dict:
    by_policy = policies(data["groups"])
    spread = seed_spread(by_policy)
    return {"seed_spread": spread, "machine_spread": data["machine_spread"],
            "finding1": finding1(by_policy, spread["spread"]), "finding2": finding2(by_policy, spread["spread"]),
            "finding3": finding3(by_policy, spread, data["binary_close"]), "finding4": finding4(data["ood"], spread)}


def _pts(c: dict | None) -> str:
    return "not run" if c is None else f"{100 * c['difference']:+.1f} (p {c['p_value']:.2g}, {c['pairs']} pairs)"


def _claims(lines: list[str], f: dict) -> None:
    lines += ["", "| claim | ours | verdict |", "|---|---|---|"]
    lines += [f"| {c['claim']} | {c['ours']} | **{c['verdict']}** |" for c in f["claims"]]


def build(result: dict) -> str:
    spread = result["seed_spread"]
    lines = ["# The paper's findings on the Object suites", "",
             "Generated by `python -m mani_skill_softvt.studies.findings` from the committed records; the rules "
             "are in its docstring. *ours*: `a>b` / `a<b` a resolved difference (p < 0.05 and beyond the "
             "training-seed spread), `none` not resolved, `unknown` the spread is not measured yet, `missing` "
             "the records have not run yet.", "", "## Training-seed spread (the yardstick)", ""]
    if spread["pairs"]:
        lines += ["| pair | TSR | DSR | TSR - DSR |", "|---|---|---|---|"]
        lines += [f"| {name} | {_pts(p['success'])} | {_pts(p['dsr_success'])} | {_pts(p['past_tolerance'])} |"
                  for name, p in spread["pairs"].items()]
        lines += ["", "Spread (largest |difference|, points): " + ", ".join(
            f"{o} {100 * v:.1f}" for o, v in spread["spread"].items())]
    else:
        lines.append("Not measured: no variant has two training seeds yet, so no difference between variants is resolved.")
    if result["machine_spread"]:
        lines += ["", "The same policy on the same ID episodes on two machines (committed records against the re-run "
                  "twins; the machine alone):", "", "| records | TSR | DSR |", "|---|---|---|"]
        lines += [f"| {name} | {_pts(m['success'])} | {_pts(m['dsr_success'])} |" for name, m in result["machine_spread"].items()]

    f1 = result["finding1"]
    lines += ["", f"## Finding 1: completion-only evaluation hides violations ({f1['verdict']})", "",
              "| variant, Object-Soft ID | episodes | TSR % | DSR % | TSR - DSR % [95% CI] | share of successes % | paper DP TSR / DSR |",
              "|---|---|---|---|---|---|---|"]
    for name, s in f1["rows"].items():
        paper = PAPER_OBJECT_SOFT.get(name.split(",")[0])
        lines.append(f"| {name} | {s['episodes']} | {percent(s['tsr'])} | {percent(s['dsr'])} | "
                     f"{percent_ci(s['gap'], s['gap_ci95'])} | {percent(s['gap_share_of_successes'])} | "
                     f"{f'{paper[1]} / {paper[2]} ({paper[0]})' if paper else '-'} |")
    if f1["gap_differences"]:
        lines += ["", "| TSR - DSR, paired (A - B) | difference |", "|---|---|"]
        lines += [f"| {name} | {_pts(g)} |" for name, g in f1["gap_differences"].items()]
    for name, m in f1["misrankings"].items():
        lines.append(f"\nTSR and DSR rank {name} in opposite orders: TSR {_pts(m['tsr'])}, DSR {_pts(m['dsr'])}.")
    _claims(lines, f1)

    f2 = result["finding2"]
    lines += ["", f"## Finding 2: the cost of deformability, rigid twins against soft objects ({f2['verdict']})", "",
              "| variant | rigid - soft TSR, paired on shared seeds | paper DP rigid / soft TSR |", "|---|---|---|"]
    for key, c in f2["pairs"].items():
        lines.append(f"| {key} | {_pts(c)} | {PAPER_RIGID_TWINS[key][0]} / {PAPER_RIGID_TWINS[key][1]} |")
    _claims(lines, f2)

    f3 = result["finding3"]
    lines += ["", f"## Finding 3: sensing against control granularity ({f3['verdict']})", "",
              "| variant | episodes | TSR % | DSR % | paper pi0.5 TSR / DSR |", "|---|---|---|---|---|"]
    for key, s in f3["rows"].items():
        paper = PAPER_ABLATION_PI05[key]
        lines.append(f"| {key} | {s['episodes'] if s else 'not run'} | {percent(s['tsr']) if s else '-'} | "
                     f"{percent(s['dsr']) if s else '-'} | {paper[0]} / {paper[1]} |")
    lines += ["", "| comparison | TSR | DSR |", "|---|---|---|"]
    for name, c in (("VO-C - VO-B (control, vision only)", f3["continuous_vs_binary"]["vo"]),
                    ("VT-C - VT-B (control, with touch)", f3["continuous_vs_binary"]["vt"]),
                    ("VT-C - VO-C (touch, continuous)", f3["touch_vs_vision"]["continuous"]),
                    ("VT-B - VO-B (touch, binary)", f3["touch_vs_vision"]["binary"])):
        lines.append(f"| {name} | {_pts(c['success'])} | {_pts(c['dsr_success'])} |")
    if f3["binary_close"]:
        lines += ["", "A binary close on each object (the expert's plan with its gripper made binary, "
                  "`studies.binary_close`): " + f3["binary_close"].get("summary", "")]
    _claims(lines, f3)

    f4 = result["finding4"]
    lines += ["", f"## Finding 4: touch under distribution shift ({f4['verdict']})", ""]
    if f4.get("pooled"):
        lines += ["| variant | OOD episodes | TSR % | DSR % | TSR - DSR % | OOD - ID twins, TSR | OOD - ID twins, DSR | "
                  "twins | paper DP TSR / DSR |", "|---|---|---|---|---|---|---|---|---|"]
        for v, p in f4["pooled"].items():
            d = f4["against_id_twins"][v]
            paper = PAPER_DP_POOLED.get(v.split(",")[0])
            lines.append(f"| {v} | {p['episodes']} | {percent(p['tsr'])} | {percent(p['dsr'])} | {percent(p['gap'])} | "
                         f"{_pts(d['tsr'])} | {_pts(d['dsr'])} | {d['twins']} | {f'{paper[0]} / {paper[2]}' if paper else '-'} |")
        lines += ["", f"VT-C - VO-C on the same OOD episodes: TSR {_pts(f4['vt_vs_vo_tsr'])}, TSR - DSR "
                  f"{_pts(f4['vt_vs_vo_gap'])} (paper DP gaps {PAPER_OOD_GAP['vo-c']} and {PAPER_OOD_GAP['vt-c']} points)."
                  + ("" if f4["complete"] else " The OOD runs are not complete (900 episodes each): no verdict yet.")]
    _claims(lines, f4)
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.studies.findings", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("results", nargs="?", type=Path, default=Path("baselines/results"),
                    help="the campaign's results directory (records, twins/, binary_close.json)")
    ap.add_argument("--out", type=Path, default=None, help="directory for findings.md/.json (default: RESULTS)")
    args = ap.parse_args(argv)
    try:
        result = analyse_findings(load(args.results))
    except ValueError as e:
        ap.error(str(e))
    text = build(result)
    out = args.out or args.results
    atomic_write(out / "findings.md", lambda p: p.write_text(text))
    atomic_write_json(out / "findings.json", result)
    print(text)
    return result


if __name__ == "__main__":
    main()
