"""The paper's findings judged by the pre-registered seed-level rule (docs/preregistration.md).

    python -m softvt_campaign.studies.seed_findings campaign-data/results

Reads every committed ID record of the four suites (``<suite>_id_<policy>[-seed<N>].jsonl``; a
file's records are one training seed of one recipe) and each soft suite's OOD records of VO-C and
VT-C, scores each seed on the registered subset (the first 25 ID episodes of each task), pools the
seed-to-seed variance over each suite's family of recipes (over the suites a claim spans when it
crosses them), and judges every registered claim, Object and Spatial, with
:mod:`mani_skill_softvt.evaluation.seed_level`; a claim whose runs are not committed yet is
*unresolved (not run)*, so each finding's verdict is given on its Object parts and on all its parts. Writes ``seed_findings.md`` and ``.json`` beside
the records: each recipe's mean over seeds with its seed-level interval and every seed's score,
then each claim with B - A, its interval, the paper's effect and the verdict, and each finding's
verdict from its parts. The claims are the registered table's; none is added or dropped here.
"""

from __future__ import annotations

import argparse
from functools import partial
from pathlib import Path

import numpy as np

from mani_skill_softvt.evaluation.seed_level import (ALPHA, contrast, episode_key, finding_verdict, first_per_task, ood_interval,
                                     outcome_of, pooled_variance, size_note, verdict)
from mani_skill_softvt.fileio import write_page
from mani_skill_softvt.tasks.suites import NUM_TASKS, OOD_CONDITIONS
from .findings import POLICIES, by_policy, id_records, load, load_ood
from .ood_results import PAPER_DP_POOLED_BY_SUITE, against_twins
from .results import PAPER_ID

PER_TASK = 25  # the registered subset: the first 25 ID episodes of each task
OUTCOME_NAMES = {"tsr": "TSR", "dsr": "DSR", "past_tolerance": "TSR - DSR"}
SPATIAL = ("spatial_soft", "spatial_rigid")
OOD_PER_TASK = 10  # the paper's OOD protocol: 10 episodes a task in each of its nine conditions (900)
OOD_EPISODES = NUM_TASKS * OOD_PER_TASK * len(OOD_CONDITIONS)


def seed_table(policies: dict, outcome: str) -> dict[tuple[str, str], list[float]]:
    """(suite, recipe) -> each complete seed's score (points) on the registered subset."""
    out = {}
    for (suite, name), seeds in sorted(policies.items()):
        scores = []
        for _, recs in sorted(seeds.items()):
            keys = first_per_task({episode_key(r) for r in recs}, PER_TASK)
            if len(keys) < PER_TASK * 10:
                continue  # a partial run is not a seed's score
            by = {episode_key(r): r for r in recs}
            scores.append(100.0 * float(np.mean([outcome_of(by[k], outcome) for k in keys])))
        if scores:
            out[(suite, name)] = scores
    return out


def family(table: dict, suites: tuple[str, ...]) -> tuple[float | None, int]:
    """The seed variance pooled over every recipe of ``suites`` (the registered families)."""
    return pooled_variance(*[v for (suite, _), v in table.items() if suite in suites])


def recipe(t: dict, outcome: str, suite: str, key: str) -> list[float]:
    """The seed scores of ``key``'s registered policy on ``suite`` (empty: not run)."""
    return t[outcome].get((suite, POLICIES[key]), [])


def not_run(text: str, paper, kind: str) -> dict:
    return {"claim": text, "paper": paper, "kind": kind, "verdict": "unresolved", "why": "not run", "comparison": None}


def judge(text: str, groups: list, weights: list, fam, paper: float, kind: str) -> dict:
    if not all(len(g) for g in groups):
        return not_run(text, paper, kind)
    c = contrast(groups, weights, fam)
    v = verdict(c, paper, kind)
    return {"claim": text, "paper": paper, "kind": kind, "verdict": v, "comparison": c.to_dict(),
            "seeds": [len(g) for g in groups], "note": size_note(c, paper) if kind == "size" and v == "supported" else None}


def ood_claims(ood: dict | None, claims_: tuple, fam: dict) -> list[dict]:
    """VT-C - VO-C on one soft suite's OOD runs (one run a recipe), clustered by initial state, with
    the ID family's seed variance added."""
    runs, names = (ood or {}).get("runs") or {}, (ood or {}).get("names") or {}
    out = []
    for text, outcome, paper in claims_:
        if "vo-c" in names and "vt-c" in names:
            # The protocol's run is all 900 episodes (docs/preregistration.md): one under way is shown, not judged.
            short = [f"{k.upper()} {len(runs[names[k]][0])} of {OOD_EPISODES}" for k in ("vo-c", "vt-c")
                     if len(runs[names[k]][0]) < OOD_EPISODES]
            if short:
                out.append({**not_run(text, paper, "sign"), "why": f"partial: {', '.join(short)}"})
                continue
            c = ood_interval(runs[names["vo-c"]][0], runs[names["vt-c"]][0], outcome, fam[outcome])
            out.append({"claim": text, "paper": paper, "kind": "sign", "verdict": verdict(c, paper, "sign"),
                        "comparison": c.to_dict(), "seeds": [1, 1]})
        else:
            out.append(not_run(text, paper, "sign"))
    return out


def claims(policies: dict, ood: dict, spatial_ood: dict | None = None) -> dict[str, list[dict]]:
    """Every registered claim, judged: the Object ones, then the Spatial ones (docs/preregistration.md,
    registered before any Spatial record existed), each part marked with ``"axis"``. ``"ID"`` holds
    the Spatial-Soft ID claims that belong to no finding."""
    t = {o: seed_table(policies, o) for o in OUTCOME_NAMES}
    soft, rigid = ("object_soft",), ("object_rigid",)
    g = partial(recipe, t)  # g(outcome, suite, variant)

    fam = {o: family(t[o], soft) for o in t}
    both = {o: family(t[o], soft + rigid) for o in t}
    out: dict[str, list[dict]] = {"1": [], "2": [], "3": [], "4": []}
    for (suite, name), scores in sorted(t["past_tolerance"].items()):
        if suite == "object_soft":
            out["1"].append({"claim": f"{name}: every seed has successes past tolerance", "paper": "> 0", "kind": "count",
                             "verdict": "supported" if min(scores) > 0 else "contradicted", "comparison": None,
                             "seeds": [len(scores)]})
    out["1"].append(judge("VT-C - VO-C, TSR - DSR", [g("past_tolerance", "object_soft", "vo-c"),
                                                      g("past_tolerance", "object_soft", "vt-c")], [-1, 1],
                          fam["past_tolerance"], 5.8, "sign"))
    tsr = judge("VO-B - VO-C, TSR (completion ranks VO-B higher)", [g("tsr", "object_soft", "vo-c"),
                                                                     g("tsr", "object_soft", "vo-b")], [-1, 1], fam["tsr"], 1.0, "sign")
    dsr = judge("VO-B - VO-C, DSR (and the deformation-aware score lower)", [g("dsr", "object_soft", "vo-c"),
                                                                              g("dsr", "object_soft", "vo-b")], [-1, 1], fam["dsr"], -1.0,
                "sign")
    tsr["paper"], dsr["paper"] = "> 0 (a misranking)", "< 0 (a misranking)"
    out["1"] += [tsr, dsr]
    out["2"].append(judge("Object-Rigid VO-C - Object-Soft VO-C, TSR", [g("tsr", "object_soft", "vo-c"),
                                                                        g("tsr", "object_rigid", "vo-c")], [-1, 1],
                          both["tsr"], 2.6, "none"))
    for text, outcome, a, b, paper, kind in (
            ("VO-C - VO-B, TSR", "tsr", "vo-b", "vo-c", 11.4, "size"),
            ("VT-C - VO-C, TSR", "tsr", "vo-c", "vt-c", -0.2, "none"),
            ("VO-C - VO-B, DSR", "dsr", "vo-b", "vo-c", 11.2, "sign"),
            ("VT-C - VT-B, DSR", "dsr", "vt-b", "vt-c", 7.0, "sign"),
            ("VT-B - VO-B, TSR", "tsr", "vo-b", "vt-b", 10.8, "sign")):
        out["3"].append(judge(text, [g(outcome, "object_soft", a), g(outcome, "object_soft", b)], [-1, 1],
                              fam[outcome], paper, kind))
    out["4"] += ood_claims(ood, (("VT-C - VO-C, pooled OOD TSR", "tsr", 2.0),
                                 ("VT-C - VO-C, pooled OOD TSR - DSR", "past_tolerance", 3.6)), fam)
    for parts in out.values():
        for p in parts:
            p["axis"] = "object"
    spatial = spatial_claims(t, spatial_ood)
    for f, parts in spatial.items():
        out.setdefault(f, []).extend(parts)
    return out


def spatial_claims(t: dict, ood: dict | None) -> dict[str, list[dict]]:
    """The Spatial claims as registered. Families: Spatial-Soft's recipes; both Spatial suites for
    the rigid-twin claims; all four suites for deformability's cost across the axes (a contrast of
    four recipes). Finding 1 counts the Spatial-Soft runs: a rigid twin cannot leave its tolerance."""
    ss, sr = ("spatial_soft",), ("spatial_rigid",)
    g = partial(recipe, t)  # g(outcome, suite, variant)

    fam = {o: family(t[o], ss) for o in t}
    spatial = {o: family(t[o], ss + sr) for o in t}
    every = {o: family(t[o], ("object_soft", "object_rigid") + ss + sr) for o in t}
    out: dict[str, list[dict]] = {"ID": [], "1": [], "2": [], "4": []}
    for text, outcome, paper in (("VT-C - VO-C, Spatial-Soft TSR", "tsr", 17.4), ("VT-C - VO-C, Spatial-Soft DSR", "dsr", 11.6)):
        out["ID"].append(judge(text, [g(outcome, "spatial_soft", "vo-c"), g(outcome, "spatial_soft", "vt-c")], [-1, 1],
                               fam[outcome], paper, "sign"))
    runs = {name: scores for (suite, name), scores in t["past_tolerance"].items() if suite == "spatial_soft"}
    for name, scores in sorted(runs.items()):
        out["1"].append({"claim": f"Spatial-Soft {name}: every seed has successes past tolerance", "paper": "> 0",
                         "kind": "count", "verdict": "supported" if min(scores) > 0 else "contradicted",
                         "comparison": None, "seeds": [len(scores)]})
    if not runs:
        out["1"].append(not_run("every Spatial-Soft policy run has successes past tolerance", "> 0", "count"))
    for key, paper, kind in (("vt-c", -22.0, "sign"), ("vo-c", -1.6, "none")):
        out["2"].append(judge(f"Spatial-Rigid {key.upper()} - Spatial-Soft {key.upper()}, TSR",
                              [g("tsr", "spatial_soft", key), g("tsr", "spatial_rigid", key)], [-1, 1],
                              spatial["tsr"], paper, kind))
    out["2"].append(judge("(Object-Rigid - Object-Soft) - (Spatial-Rigid - Spatial-Soft), VO-C TSR: deformability's "
                          "cost changes sign between the axes",
                          [g("tsr", s, "vo-c") for s in ("object_soft", "object_rigid", "spatial_soft", "spatial_rigid")],
                          [-1, 1, 1, -1], every["tsr"], 4.2, "sign"))
    out["4"] += ood_claims(ood, (("VT-C - VO-C, pooled OOD TSR (Spatial-Soft)", "tsr", 14.2),
                                 ("VT-C - VO-C, pooled OOD TSR - DSR (Spatial-Soft)", "past_tolerance", 5.2)), fam)
    for parts in out.values():
        for p in parts:
            p["axis"] = "spatial"
    return out


def misranking(parts: list[dict]) -> str:
    """Completion misranks VO-B against VO-C when TSR ranks it higher and DSR lower, both resolved."""
    return "supported" if all(p["verdict"] == "supported" for p in parts) else "unresolved"


def finding_verdicts(judged: dict[str, list[dict]], axes: tuple[str, ...]) -> dict[str, str]:
    """Each finding's verdict from its parts on ``axes`` (the ``"ID"`` claims belong to no finding)."""
    verdicts = {}
    for f, parts in judged.items():
        parts = [p for p in parts if p.get("axis", "object") in axes]
        if f == "ID" or not parts:
            continue
        # Finding 1's misranking is one claim of two parts.
        rest = [p["verdict"] for p in parts if not p["claim"].startswith("VO-B - VO-C")]
        ranks = [p for p in parts if p["claim"].startswith("VO-B - VO-C")]
        verdicts[f] = finding_verdict(rest + ([misranking(ranks)] if ranks else []))
    return verdicts


def seed_mean(scores: list[float]) -> str:
    """``81.8 (2 seeds)``; ``not run`` for none."""
    return f"{np.mean(scores):.1f} ({len(scores)} seed{'s' * (len(scores) != 1)})" if scores else "not run"


def pooled_ood(ood: dict | None, key: str) -> dict | None:
    """One soft suite's OOD run of ``key`` pooled over its conditions: ``episodes``, TSR and DSR
    (points), each with its change against the run's ID twins paired on the initial state (None
    before the twins have run; :func:`ood_results.against_twins`); ``{"error": ...}`` where the runs
    could not be read; None if not run."""
    if (ood or {}).get("error"):
        return {"error": ood["error"]}
    names = (ood or {}).get("names") or {}
    if key not in names:
        return None
    recs, twins = ood["runs"][names[key]][0], (ood.get("twins_from") or {}).get(names[key])
    out = {"episodes": len(recs), "twins": len(twins or [])}
    for name, outcome in (("tsr", "success"), ("dsr", "dsr_success")):
        out[name] = 100.0 * float(np.mean([bool(r[outcome]) for r in recs]))
        out[f"{name}_change"] = 100.0 * against_twins(recs, twins, outcome)["difference"] if twins else None
    return out


def ood_cell(pooled: dict | None, outcome: str) -> str:
    """``59.8 (-30.2)``; a run short of the protocol's episodes says so, as does a change read on part
    of its ID twins (paired on the scenes they have) and a run that could not be read."""
    if pooled is None or "error" in pooled:
        return "not run" if pooled is None else "error (ood.md says)"
    full, scenes = OOD_EPISODES, NUM_TASKS * OOD_PER_TASK
    change = pooled[f"{outcome}_change"]
    if change is None:
        change_text = "-"
    else:
        change_text = f"{change:+.1f}" + (f" on {pooled['twins']} of {scenes} twins" if pooled["twins"] < scenes else "")
    text = f"{pooled[outcome]:.1f} ({change_text})"
    return text if pooled["episodes"] >= full else f"partial, {pooled['episodes']} of {full}: {text}"


def paper_table_lines(tables: dict, ood_by_suite: dict[str, dict | None]) -> list[str]:
    """The paper's Diffusion Policy tables in its layout (ID, rigid twins, OOD pooled), ours beside
    each of its cells: the mean over training seeds on the registered subset (ID), one run (OOD)."""
    def cell(ours: str, paper) -> str:
        return f"{ours} / {paper if paper is not None else '-'}"

    lines = ["", "## The paper's tables: ours / the paper's Diffusion Policy", "",
             f"ID, mean over training seeds on the first {PER_TASK} ID episodes of each task (each seed on all "
             "500 and the intervals: results.md and the recipe table above):", "",
             "| input | Object-Soft TSR | Object-Soft DSR | Spatial-Soft TSR | Spatial-Soft DSR |", "|---|---|---|---|---|"]
    for key in ("vo-c", "vt-c"):
        cells = [cell(seed_mean(recipe(tables, o, suite, key)), (PAPER_ID[suite][key][1 + (o == "dsr")]))
                 for suite in ("object_soft", "spatial_soft") for o in ("tsr", "dsr")]
        lines.append(f"| {key.upper()} | " + " | ".join(cells) + " |")
    lines += ["", "Rigid twins (TSR; on a twin DSR is TSR):", "",
              "| input | Object Rigid | Object Soft | Spatial Rigid | Spatial Soft |", "|---|---|---|---|---|"]
    for key in ("vo-c", "vt-c"):
        cells = [cell(seed_mean(recipe(tables, "tsr", suite, key)), PAPER_ID[suite][key][1])
                 for suite in ("object_rigid", "object_soft", "spatial_rigid", "spatial_soft")]
        lines.append(f"| {key.upper()} | " + " | ".join(cells) + " |")
    lines += ["", "OOD pooled over the nine conditions (one run a recipe; the change against its ID twins, the "
              "paper's against its full ID entry):", "",
              "| input | Object-Soft TSR (change) | Object-Soft DSR (change) | Spatial-Soft TSR (change) "
              "| Spatial-Soft DSR (change) |", "|---|---|---|---|---|"]
    for key in ("vo-c", "vt-c"):
        cells = []
        for suite in ("object_soft", "spatial_soft"):
            ours, paper = pooled_ood(ood_by_suite.get(suite), key), PAPER_DP_POOLED_BY_SUITE[suite][key]
            for i, outcome in ((0, "tsr"), (2, "dsr")):
                cells.append(cell(ood_cell(ours, outcome), f"{paper[i]} ({paper[i + 1]:+})"))
        lines.append(f"| {key.upper()} | " + " | ".join(cells) + " |")
    return lines


def build(policies: dict, ood: dict, spatial_ood: dict | None = None) -> tuple[str, dict]:
    judged = claims(policies, ood, spatial_ood)
    verdicts = finding_verdicts(judged, ("object", "spatial"))
    object_verdicts = finding_verdicts(judged, ("object",))
    lines = ["# The paper's findings by the pre-registered seed-level rule", "",
             f"Generated by `python -m softvt_campaign.studies.seed_findings` (rule: docs/preregistration.md). "
             f"Each seed is scored on the first {PER_TASK} ID episodes of each task; B - A over training seeds, "
             f"Student's t with the seed variance pooled over the suite's recipes, {int(100 * (1 - ALPHA))} % intervals.",
             "", "## Recipes: mean over training seeds", "",
             "| suite | recipe | seeds | " + " | ".join(f"{n} mean [95% CI]; seeds" for n in OUTCOME_NAMES.values()) + " |",
             "|---|---|---|---|---|---|"]
    tables = {o: seed_table(policies, o) for o in OUTCOME_NAMES}
    for key in sorted(tables["tsr"]):
        cells = []
        for o in OUTCOME_NAMES:
            scores = tables[o][key]
            fam = family(tables[o], (key[0],))
            c = contrast([scores], [1.0], fam)
            # A rate's interval is shown within [0, 100]; the t interval itself can pass them.
            ci = f"[{max(0.0, c.ci95[0]):.1f}, {min(100.0, c.ci95[1]):.1f}]" if c.ci95 else "[no interval]"
            cells.append(f"{np.mean(scores):.1f} {ci}; " + ", ".join(f"{x:.1f}" for x in scores))
        lines.append(f"| {key[0]} | {key[1]} | {len(tables['tsr'][key])} | " + " | ".join(cells) + " |")
    for axis, title in (("object", "Claims: Object suites"), ("spatial", "Claims: Spatial suites (registered before any Spatial record)")):
        lines += ["", f"## {title}", "", "| finding | claim (B - A, points) | seeds | ours [95% CI] | df | paper | kind | verdict |",
                  "|---|---|---|---|---|---|---|---|"]
        for f, parts in judged.items():
            for p in (p for p in parts if p.get("axis", "object") == axis):
                c = p.get("comparison")
                ours = "-" if c is None else (f"{c['difference']:+.1f} " + (f"[{c['ci95'][0]:+.1f}, {c['ci95'][1]:+.1f}]"
                                                                             if c["ci95"] else "[no interval]"))
                lines.append(f"| {f} | {p['claim']} | {p.get('seeds', '-')} | {ours} | {c['df'] if c else '-'} | {p['paper']} "
                             f"| {p['kind']} | {p['verdict']}{', ' + p['note'] if p.get('note') else ''}"
                             f"{' (' + p['why'] + ')' if p.get('why') else ''} |")
    lines += paper_table_lines(tables, {"object_soft": ood, "spatial_soft": spatial_ood})
    lines += ["", "## Findings", "", "| finding | on its Object parts | on all its registered parts | parts run |", "|---|---|---|---|"]
    for f, v in verdicts.items():
        parts = judged[f]
        run = sum(1 for p in parts if not p.get("why"))  # not run, or a run under way
        lines.append(f"| {f} | {object_verdicts.get(f, '-')} | {v} | {run} of {len(parts)} |")
    lines += ["", "Finding 1's misranking needs both of its parts supported (VO-B above VO-C on TSR, below it on DSR).",
              "OOD claims: one run a recipe, clustered by initial state, with the ID family's seed variance added.",
              "A part not run yet is unresolved, and an unresolved part never makes a finding contradicted."]
    return "\n".join(lines) + "\n", {"claims": judged, "verdicts": verdicts, "verdicts_object_parts": object_verdicts}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=Path, nargs="?", default=Path("campaign-data/results"))
    args = ap.parse_args(argv)
    try:
        found = load(args.results)  # the records the findings read, each verified
    except ValueError as e:
        ap.error(str(e))
    spatial = by_policy(id_records(args.results, SPATIAL))
    text, data = build({**found["policies"], **spatial}, found["ood"], load_ood(args.results, "spatial_soft"))
    write_page(args.results, "seed_findings", text, data)
    print(text)
    return data


if __name__ == "__main__":
    main()
