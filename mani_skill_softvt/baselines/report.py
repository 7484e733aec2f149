"""The baselines' results beside the paper's: TSR, DSR, TSR - DSR and its share of successes.

    python -m mani_skill_softvt.baselines.report baselines/results/object_soft_id_*.jsonl

Reads evaluation records (each verified against its hash), groups them by the policy's name in
the receipt (``diffusion_policy[vo-c,cpu]``, ...: variant and recipe), and writes ``<out>/results.md`` and ``.json``: per
variant the episode count, TSR and DSR with 95 % Wilson intervals, the gap TSR - DSR (successes
that left the calibrated tolerance) and its share of the successes, how episodes ended, how many
episodes of any ending squeezed the object past its tolerance (R_max > 1, or crushed until the
FEM blew up: harm that TSR - DSR cannot show when a policy never succeeds), and the paper's
numbers for the same configuration.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..evaluation.metrics import summarize
from ..evaluation.runner import read_records
from ..fileio import atomic_write, atomic_write_json

# The paper's ID results on Object-Soft (main results table; the binary ablation table). Its B
# variants are pi0.5's ablations, not Diffusion Policy's: the paper trains no binary DP.
PAPER_OBJECT_SOFT = {
    "vo-c": ("Diffusion Policy", 37.4, 33.6),
    "vt-c": ("Diffusion Policy", 40.0, 30.4),
    "vo-b": ("pi0.5 (binary ablation)", 30.2, 27.2),
    "vt-b": ("pi0.5 (binary ablation)", 41.0, 28.0),
}


def variant_of(record: dict) -> str:
    """``diffusion_policy[vt-c,cpu,rgb+depth]`` -> ``vt-c,cpu,rgb+depth`` (variant first)."""
    name = record["receipt"]["policy"]
    return name[name.index("[") + 1:name.index("]")] if "[" in name else name


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


def _ci(x: float, ci) -> str:
    return "- (no successes)" if ci is None else f"{_pct(x)} [{_pct(ci[0])}, {_pct(ci[1])}]"


def build(records: list[dict]) -> tuple[str, dict]:
    groups: dict[str, list[dict]] = {}
    for r in records:
        groups.setdefault((r["suite"], r["condition"], variant_of(r)), []).append(r)
    data, lines = {}, []
    header = ("| suite | protocol | variant | episodes | TSR % [95% CI] | DSR % [95% CI] | TSR-DSR % [95% CI] | share of successes % [95% CI] "
              "| paper TSR / DSR (model) |\n|---|---|---|---|---|---|---|---|---|")
    lines.append(header)
    for (suite, condition, variant), recs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] != "id", kv[0][2])):
        s = summarize(recs)
        protocol = "ID" if condition == "id" else f"OOD {condition}"
        paper = PAPER_OBJECT_SOFT.get(variant.split(",")[0]) if suite == "object_soft" and condition == "id" else None
        data[f"{suite}/{condition}/{variant}"] = {**s, "paper": paper}
        (lo_t, hi_t), (lo_d, hi_d) = s["tsr_ci95"], s["dsr_ci95"]
        lines.append(f"| {suite} | {protocol} | {variant} | {s['episodes']} | {_pct(s['tsr'])} [{_pct(lo_t)}, {_pct(hi_t)}] "
                     f"| {_pct(s['dsr'])} [{_pct(lo_d)}, {_pct(hi_d)}] "
                     f"| {_pct(s['gap'])} [{_pct(s['gap_ci95'][0])}, {_pct(s['gap_ci95'][1])}] "
                     f"| {_ci(s['gap_share_of_successes'], s['gap_share_ci95'])} "
                     f"| {f'{paper[1]} / {paper[2]} ({paper[0]})' if paper else '-'} |")
    lines += ["", "| variant | " + " | ".join(("success", "dropped", "timeout", "sim_unstable", "policy_error",
                                                "worker_died")) + " | past tolerance (R_max > 1 or crushed), any end | median R_max |", "|---" * 9 + "|"]
    for key, s in data.items():
        t = s["terminations"]
        lines.append(f"| {key} | " + " | ".join(str(t.get(k, 0)) for k in ("success", "dropped", "timeout", "sim_unstable",
                                                                          "policy_error", "worker_died"))
                     + f" | {s['tolerance_violations']} | {s['r_max_median']:.3f} |")
    return "\n".join(lines) + "\n", data


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("records", nargs="+", type=Path, help="evaluation record files (JSONL)")
    ap.add_argument("--out", type=Path, default=None, help="directory for results.md/.json (default: the records')")
    args = ap.parse_args(argv)
    records = [r for path in args.records for r in read_records(path)]
    if not records:
        ap.error("no records in the given files")
    text, data = build(records)
    out = args.out or args.records[0].parent
    atomic_write(out / "results.md", lambda p: p.write_text(text))
    atomic_write_json(out / "results.json", data)
    print(text)
    return data


if __name__ == "__main__":
    main()
