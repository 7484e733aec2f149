"""The baselines' results beside the paper's: TSR, DSR, TSR - DSR and its share of successes.

    python -m softvt_campaign.studies.results campaign-data/results/object_soft_id_*.jsonl \
        --legacy campaign-data/results/old_physics/*.jsonl

Reads evaluation records (each verified against its hash), groups them by the policy's name in
the receipt (``diffusion_policy[vo-c,cpu]``, ...: variant and recipe) and, for trained policy
files, by the file (its name and, where two files of one name were scored, its SHA-256), and writes ``<out>/results.md`` and ``.json``: per
variant the episode count, TSR and DSR with 95 % Wilson intervals, the gap TSR - DSR (successes
that left the calibrated tolerance) and its share of the successes, how episodes ended, how many
episodes of any ending squeezed the object past its tolerance (R_max > 1, a collapsed tet, or a
blown-up FEM: harm that TSR - DSR cannot show when a policy never succeeds) and in how many a tet
collapsed, and the paper's
numbers for the same configuration. On a Spatial suite, which instance each row carried, by the
instructed side (the other instance on the target, both disturbed). Then TSR / DSR per task side by side, and every two of
today's variants compared on the episodes both ran (the protocol's seeds are the same for every
policy, so the comparison is paired: exact McNemar p-values and Newcombe's paired 95 % interval of the
difference), and each variant on a soft suite
against the same variant trained on its rigid twin suite, paired on the seeds both draw (the
paper's rigid-twin comparison). Each side-swap row against its ID row, paired on task and seed:
the TSR change and which instance the policy carried in both episodes of a pair. ``<out>/success_traces.png`` draws
the R_t traces of each variant's successes, within and beyond the tolerance (the paper's
qualitative figure). Records given with ``--legacy`` (made under an older physics or sensor) are
rows of their own, marked ``[old physics]``, never pooled with today's nor compared with them.
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

from matplotlib.figure import Figure

from mani_skill_softvt.evaluation.metrics import (group_summaries, instance_outcomes, paired_comparison, percent,
                                                  percent_ci, side_swap_agreement, summarize)
from mani_skill_softvt.evaluation.protocols import episode_key, scene_key, seed_key
from mani_skill_softvt.evaluation.sidecar import crossing_note, machine, numerics, sidecar
from mani_skill_softvt.evaluation.records import read_records
from mani_skill_softvt.evaluation.report import rt_series
from mani_skill_softvt.evaluation.run import policy_tag
from mani_skill_softvt.fileio import atomic_write, atomic_write_json
from mani_skill_softvt.provenance import today_data_path
from mani_skill_softvt.tasks.suites import get_suite, task_spec

# The paper's ID results by suite (its main results table, Diffusion Policy; the binary ablation
# table, whose B variants are pi0.5's: the paper trains no binary DP; the rigid-twin table, which
# reports TSR alone since DSR coincides with it on twins): model, TSR, DSR (None: not reported).
PAPER_ID = {
    "object_soft": {"vo-c": ("Diffusion Policy", 37.4, 33.6), "vt-c": ("Diffusion Policy", 40.0, 30.4),
                    "vo-b": ("pi0.5 (binary ablation)", 30.2, 27.2), "vt-b": ("pi0.5 (binary ablation)", 41.0, 28.0)},
    "spatial_soft": {"vo-c": ("Diffusion Policy", 15.6, 13.4), "vt-c": ("Diffusion Policy", 33.0, 25.0)},
    "object_rigid": {"vo-c": ("Diffusion Policy", 40.0, None), "vt-c": ("Diffusion Policy", 35.0, None)},
    "spatial_rigid": {"vo-c": ("Diffusion Policy", 14.0, None), "vt-c": ("Diffusion Policy", 11.0, None)},
}
PAPER_OBJECT_SOFT = PAPER_ID["object_soft"]  # the Object findings read these


def paper_id_cell(paper: tuple | None) -> str:
    """``37.4 / 33.6 (Diffusion Policy)``; a twin's ``40.0 / = TSR (...)``; ``-`` where the paper has none."""
    if paper is None:
        return "-"
    model, tsr, dsr = paper
    return f"{tsr} / {'= TSR' if dsr is None else dsr} ({model})"


LEGACY_MARK = " [old physics]"  # ends the row label of records made under an older physics or sensor
ENDINGS = ("success", "dropped", "timeout", "sim_unstable", "policy_error", "worker_died")


def variant_of(record: dict) -> str:
    """``diffusion_policy[vt-c,cpu,rgb+depth]`` -> ``vt-c,cpu,rgb+depth`` (variant first)."""
    name = record["receipt"].get("policy") or record["policy"]  # a worker_died record's receipt has no name
    return name[name.index("[") + 1:name.index("]")] if "[" in name else name


def group_labels(records: list[dict], legacy: bool = False) -> list[str]:
    """Each record's row label: the variant, the policy file's name for a trained policy, its
    hash's start where files of one name differ, and ``[old physics]`` for legacy records."""
    # A worker_died record names no variant (its policy never ran): it takes that of its file's other records.
    # Keyed by the policy path as it is spelled today: a file's old records name baselines/policies/.
    named = {today_data_path(r["policy"]): variant_of(r) for r in records if r["receipt"].get("policy")}

    def base(r):
        label = variant_of(r) if r["receipt"].get("policy") else named.get(today_data_path(r["policy"]), variant_of(r))
        return f"{label} ({policy_tag(r['policy'])})" if str(r["policy"]).endswith(".pt") else label

    # Files of one name on different suites (a variant and its rigid-twin training) are rows of
    # their own suite already: only files of one name on one suite need the hash to tell them apart.
    hashes: dict[tuple[str, str], set] = {}
    for r in records:  # a record from before the hash was kept is of whichever file it names
        hashes.setdefault((r["suite"], base(r)), set()).update({r["policy_sha256"]} if r.get("policy_sha256") else set())
    out = []
    for r in records:
        label = base(r)
        if len(hashes[(r["suite"], label)]) > 1 and r.get("policy_sha256"):
            label += f" sha {r['policy_sha256'][:8]}"
        out.append(label + (LEGACY_MARK if legacy else ""))
    return out


def is_legacy(key: tuple[str, str, str]) -> bool:
    """The group (suite, condition, label) holds records made under an older physics or sensor."""
    return key[2].endswith(LEGACY_MARK)


def grouped(records: list[dict], legacy: list[dict] = ()) -> dict[tuple[str, str, str], list[dict]]:
    """Records by (suite, condition, row label), today's first, the legacy rows marked. An
    episode twice in one row (overlapping files, say) is an error, not a double count."""
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for recs, old in ((records, False), (list(legacy), True)):
        for r, label in zip(recs, group_labels(recs, old)):
            groups.setdefault((r["suite"], r["condition"], label), []).append(r)
    for key, recs in groups.items():
        keys = [episode_key(r) for r in recs]
        if len(set(keys)) < len(keys):
            twice = next(k for k in keys if keys.count(k) > 1)
            raise ValueError(f"row {key[2]!r}: episode {twice} (suite, task, condition, seed) is in the given records "
                             f"twice; give each record file once")
    return groups


def per_task_lines(groups: dict) -> list[str]:
    """Per suite of today's rows, TSR / DSR (%) of each task (with its object), one column per
    variant (and protocol, where there are several); none for legacy rows, whose per-task tables
    sit beside their records."""
    lines = []
    for suite in sorted({k[0] for k in groups if not is_legacy(k)}):
        keys = sorted(k for k in groups if k[0] == suite and not is_legacy(k))
        per = {k: {t[0]: s for t, s in group_summaries(groups[k], ("task_id",)).items()} for k in keys}
        several = len({k[1] for k in keys}) > 1
        names = [f"{k[1]}/{k[2]}" if several else k[2] for k in keys]
        lines += ["", f"Per task, {suite}:", "",
                  "| task | " + " | ".join(f"{n} TSR / DSR %" for n in names) + " |", "|---" * (len(keys) + 1) + "|"]
        for t in sorted({t for k in keys for t in per[k]}):
            cells = [f"{percent(per[k][t]['tsr'], 0)} / {percent(per[k][t]['dsr'], 0)} of {per[k][t]['episodes']}"
                     if t in per[k] else "-" for k in keys]
            lines.append(f"| {t} ({task_spec(suite, t).asset_id}) | " + " | ".join(cells) + " |")
    return lines


def by_instructed_instance(recs: list[dict]) -> dict[str, dict] | None:
    """A Spatial row's episodes, all of them and then those of each instructed instance: the
    episode count, TSR with its interval, and how many ended with the other instance on the
    target or both disturbed. None for a row that is not a Spatial one (or whose records predate
    the instances being kept). The ID protocol fixes the side per task (right in tasks 1 and 6,
    left in the other eight), so a policy that never reads the instruction (the paper's Diffusion
    Policy, ours) can tell the side only from the object; its errors by side say whether it did
    (issue 61's question)."""
    if instance_outcomes(recs) is None:
        return None
    out = {}
    side_of = lambda r: r.get("instructed_instance") or "unrecorded"  # noqa: E731 (a dead worker's record names none)
    for side in ("all", *sorted({side_of(r) for r in recs})):
        s = summarize([r for r in recs if side == "all" or side_of(r) == side])
        out[side] = {"episodes": s["episodes"], "tsr": s["tsr"], "tsr_ci95": s["tsr_ci95"],
                     "wrong_instance": s["instances"]["wrong_instance"], "both_disturbed": s["instances"]["both_disturbed"]}
    return out


def instance_lines(groups: dict) -> list[str]:
    """The "Which instance" table: each Spatial row of today's by instructed instance
    (``by_instructed_instance``)."""
    lines = []
    for key in sorted(k for k in groups if not is_legacy(k)):
        sides = by_instructed_instance(groups[key])
        if sides is None:
            continue
        if not lines:
            lines = ["", "Which instance (Spatial suites; a success is the instructed one on the target):", "",
                     "| row | instructed | episodes | TSR % [95% CI] | the other instance on the target "
                     "| both instances disturbed |", "|---|---|---|---|---|---|"]
        for side, s in sides.items():
            lines.append(f"| {'/'.join(key)} | {side} | {s['episodes']} | {percent_ci(s['tsr'], s['tsr_ci95'])} "
                         f"| {s['wrong_instance']} | {s['both_disturbed']} |")
    return lines


def side_swaps(groups: dict) -> dict[str, dict]:
    """Each of today's side-swap rows against the same variant's ID row, paired on task and seed
    (the same scene, the other instance instructed): the TSR change, and which instance it carried
    in each (:func:`side_swap_agreement`)."""
    out = {}
    for suite, condition, variant in sorted(k for k in groups if not is_legacy(k)):
        if condition == "side_swap" and (ids := groups.get((suite, "id", variant))):
            swap = groups[(suite, condition, variant)]
            pair = {**side_swap_agreement(ids, swap), "success": paired_comparison(swap, ids, "success", scene_key)}
            if pair["pairs"]:  # a swap run on seeds the ID run never drew pairs with nothing
                out[f"{suite}/{variant}"] = pair
    return out


def side_swap_lines(swaps: dict[str, dict]) -> list[str]:
    if not swaps:
        return []
    lines = ["", "The side swap against ID, paired on task and seed (the same scene, the other instance instructed): "
             "a policy that reads the instruction carries the instructed instance in both; one that does not "
             "carries the same instance in both, so its swap successes are its ID run's wrong instances:", "",
             "| row | pairs | swap TSR - ID TSR (points) [95% CI] | McNemar p | the instructed instance in both "
             "| the same instance in both |", "|---|---|---|---|---|---|"]
    for name, s in swaps.items():
        c = s["success"]
        lo, hi = c["difference_ci95"]
        lines.append(f"| {name} | {s['pairs']} | {100 * c['difference']:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}] "
                     f"| {c['p_value']:.2g} | {s['followed']} | {s['same_instance']} |")
    return lines


def comparisons(groups: dict) -> dict[str, dict]:
    """Every two of today's variants of one suite and protocol, paired on their common episodes,
    and each variant on a soft suite against the same variant (its own training) on the rigid
    twin suite, paired on the shared seeds (the paper's rigid-twin comparison): TSR and DSR."""
    out = {}
    today = sorted(k for k in groups if not is_legacy(k))
    for a, b in itertools.combinations(today, 2):
        if a[:2] == b[:2]:
            pair = {o: paired_comparison(groups[a], groups[b], o) for o in ("success", "dsr_success")}
            if pair["success"]["pairs"]:
                out[f"{a[0]}/{a[1]}: {a[2]} vs {b[2]}"] = pair
    for soft in (k for k in today if not get_suite(k[0]).rigid):
        for rigid in (k for k in today if k[0] == get_suite(soft[0]).twin and k[1] == soft[1]):
            if variant_name(soft[2]) == variant_name(rigid[2]):
                pair = {o: paired_comparison(groups[soft], groups[rigid], o, seed_key) for o in ("success", "dsr_success")}
                if pair["success"]["pairs"]:
                    out[f"{soft[1]}: {soft[0]} {soft[2]} vs {rigid[0]} {rigid[2]}"] = pair
    return out


def variant_name(label: str) -> str:
    """A row label's variant and recipe (``vo-c,cpu`` of ``vo-c,cpu vo-c-cpu.pt``)."""
    return label.split(" ")[0]


def comparison_lines(pairs: dict[str, dict]) -> list[str]:
    lines = ["| comparison (A vs B) | outcome | pairs | both | only A | only B | neither | A - B (points) [95% CI] | McNemar p |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, pair in pairs.items():
        for outcome, label in (("success", "task success"), ("dsr_success", "deformation-aware success")):
            c = pair[outcome]
            lo, hi = c["difference_ci95"]
            lines.append(f"| {name} | {label} | {c['pairs']} | {c['both']} | {c['only_a']} | {c['only_b']} | "
                         f"{c['neither']} | {100 * c['difference']:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}] | {c['p_value']:.2g} |")
    return lines


def plot_success_traces(groups: dict, out: Path) -> Path | None:
    """R_t of each of today's variants' successes against time, green within the tolerance, red
    beyond it (R_max > 1 or a tet collapsed). With no success to draw, no figure: a previous one
    at ``out`` is removed (it would show other records) and None returned."""
    today = [(k, [r for r in groups[k] if r["success"] and r.get("deformation_trace")])
             for k in sorted(groups) if not is_legacy(k)]
    today = [(k, recs) for k, recs in today if recs]
    if not today:
        Path(out).unlink(missing_ok=True)
        return None

    fig = Figure(figsize=(4.2 * len(today), 3.4))
    axes = fig.subplots(1, len(today), squeeze=False, sharey=True)
    peak = max(r["r_max"] for _, recs in today for r in recs)
    for ax, ((suite, condition, label), recs) in zip(axes[0], today):
        within = sum(r["dsr_success"] for r in recs)
        for r in sorted(recs, key=lambda r: not r["dsr_success"]):  # the fewer red ones on top
            ax.plot(*rt_series(r), lw=0.6, alpha=0.35, color="tab:green" if r["dsr_success"] else "tab:red")
        ax.axhline(1.0, color="k", ls="--", lw=1)
        ax.set_title(f"{label}\n{suite} {condition}: {within} of {len(recs)} successes within tolerance", fontsize=8)
        ax.set_xlabel("time (s)")
        ax.set_ylim(0, min(max(1.2, 1.05 * peak), 4.0))  # a few crushing peaks would flatten the rest
    axes[0][0].set_ylabel("R_t = D_t / tau_o")
    axes[0][0].plot([], [], color="tab:green", label="within tolerance")
    axes[0][0].plot([], [], color="tab:red", label="beyond (R_max > 1 or a tet collapsed)")
    axes[0][0].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    atomic_write(out, lambda p: fig.savefig(p, format="png", dpi=120))
    return out


def build(groups: dict[tuple[str, str, str], list[dict]]) -> tuple[str, dict]:
    """The report's markdown and its JSON: ``rows`` (one summary per row of the main table) and
    ``comparisons`` (today's variants paired)."""
    rows, lines = {}, []
    header = ("| suite | protocol | variant | episodes | TSR % [95% CI] | DSR % [95% CI] | TSR-DSR % [95% CI] | share of successes % [95% CI] "
              "| paper TSR / DSR (model) |\n|---|---|---|---|---|---|---|---|---|")
    lines.append(header)
    for (suite, condition, variant), recs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] != "id", kv[0][2])):
        s = summarize(recs)
        protocol = {"id": "ID", "side_swap": "side swap", "placement_x2": "placement x2"}.get(condition, f"OOD {condition}")
        paper = PAPER_ID.get(suite, {}).get(variant.split(",")[0].split(" ")[0]) if condition == "id" else None
        rows[f"{suite}/{condition}/{variant}"] = {**s, "paper": paper}
        if (sides := by_instructed_instance(recs)) is not None:
            rows[f"{suite}/{condition}/{variant}"]["by_instructed_instance"] = sides
        lines.append(f"| {suite} | {protocol} | {variant} | {s['episodes']} | {percent_ci(s['tsr'], s['tsr_ci95'])} "
                     f"| {percent_ci(s['dsr'], s['dsr_ci95'])} | {percent_ci(s['gap'], s['gap_ci95'])} "
                     f"| {percent_ci(s['gap_share_of_successes'], s['gap_share_ci95'])} "
                     f"| {paper_id_cell(paper)} |")
    columns = (*ENDINGS, "past tolerance (R_max > 1, collapsed or blown up), any end", "a tet collapsed", "median R_max")
    lines += ["", "| variant | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for key, s in rows.items():
        ends = [str(s["terminations"].get(k, 0)) for k in ENDINGS]
        lines.append(f"| {key} | " + " | ".join(ends) + f" | {s['tolerance_violations']} | {s['collapses']} "
                     f"| {s['r_max_median']:.3f} |")
    lines += instance_lines(groups)
    lines += per_task_lines(groups)
    pairs = comparisons(groups)
    if pairs:
        lines += ["", "Paired on the same episodes (p: exact McNemar, two-sided, each comparison on its own: "
                  "no correction for making several):", "", *comparison_lines(pairs)]
    swaps = side_swaps(groups)
    lines += side_swap_lines(swaps)
    return "\n".join(lines) + "\n", {"rows": rows, "comparisons": pairs, "side_swaps": swaps}


def provenance_lines(files: list[tuple[str, list[dict], dict | None]]) -> list[str]:
    """Where each records file ran (its records' stack and numerics, else its provenance sidecar
    entry), and what the rows may compare when they cross machines or numerics (``sidecar.crossing_note``)."""
    lines = ["", "| records file | machine | numerics | evidence (sidecar) |", "|---|---|---|---|"]
    rows = [(machine(recs, entry), numerics(recs, entry)) for _, recs, entry in files]
    for (name, _, entry), (where, made_under) in zip(files, rows):
        lines.append(f"| {name} | {where} | {made_under} | {(entry or {}).get('evidence', '-')} |")
    note = crossing_note(rows)
    if note:
        lines.append(f"\n{note}")
    return lines


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m softvt_campaign.studies.results", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("records", nargs="*", type=Path, help="evaluation record files (JSONL)")
    ap.add_argument("--legacy", nargs="*", type=Path, default=[],
                    help="record files made under an older physics or sensor: rows of their own, marked [old physics]")
    ap.add_argument("--out", type=Path, default=None,
                    help="directory for results.md/.json (default: the records' directory, or the --legacy files' parent's)")
    args = ap.parse_args(argv)
    records = [r for path in args.records for r in read_records(path)]
    legacy = [r for path in args.legacy for r in read_records(path)]
    if not records and not legacy:
        ap.error("no records in the given files")
    try:
        groups = grouped(records, legacy)
    except ValueError as e:
        ap.error(str(e))
    text, data = build(groups)
    files = [(p.name, read_records(p), sidecar(p)) for p in [*args.records, *args.legacy]]
    text += "\n".join(provenance_lines(files)) + "\n"
    out = args.out or (args.records or [args.legacy[0].parent.parent])[0]
    out = out.parent if out.suffix == ".jsonl" else out
    atomic_write(out / "results.md", lambda p: p.write_text(text))
    atomic_write_json(out / "results.json", data)
    plot_success_traces(groups, out / "success_traces.png")
    print(text)
    return data


if __name__ == "__main__":
    main()
