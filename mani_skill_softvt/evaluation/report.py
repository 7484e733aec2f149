"""Reports of an evaluation: markdown and JSON tables, R_t traces, OOD per-factor curves."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..fileio import atomic_write, atomic_write_json
from ..physics.constants import CONTROL_FREQ
from ..tasks.suites import OOD_CONDITIONS, PhysicalFactors
from .metrics import DISTURBED_M, deformation_ratio, group_summaries, percent, percent_ci, summarize
from .runner import TERMINATIONS


def _row(label: str, s: dict) -> str:
    return (f"| {label} | {s['episodes']} | {percent_ci(s['tsr'], s['tsr_ci95'])} | "
            f"{percent_ci(s['dsr'], s['dsr_ci95'])} | {percent(s['gap'])} | {percent(s['gap_share_of_successes'])} | "
            f"{s['r_max_median']:.3f} |")


HEADER = ("| group | episodes | TSR % [95% CI] | DSR % [95% CI] | TSR-DSR | share of successes % | median R_max |\n"
          "|---|---|---|---|---|---|---|")


def _termination_table(per_suite: dict) -> list[str]:
    cols = list(TERMINATIONS) + sorted({k for s in per_suite.values() for k in s["terminations"]} - set(TERMINATIONS))
    lines = ["| group | " + " | ".join(cols) + " | tolerance violations | of them a tet collapsed |",
             "|---" * (len(cols) + 3) + "|"]
    for label, s in per_suite.items():
        counts = [str(s["terminations"].get(c, 0)) for c in cols]
        lines.append(f"| {label} | " + " | ".join(counts) + f" | {s['tolerance_violations']} | {s['collapses']} |")
    return lines


def build_report(records: list[dict]) -> tuple[str, dict]:
    """Markdown text and a JSON-able dict: overall, per suite, per task, per OOD condition."""
    data = {"overall": summarize(records),
            "per_suite": {k[0]: v for k, v in group_summaries(records, ("suite",)).items()},
            "per_task": {f"{k[0]}/{k[1]}": v for k, v in group_summaries(records, ("suite", "task_id")).items()},
            "per_condition": {f"{k[0]}/{k[1]}": v for k, v in group_summaries(records, ("suite", "condition")).items()}}
    lines = ["## Overall", HEADER, _row("all", data["overall"]), "", "## Per suite", HEADER]
    lines += [_row(k, v) for k, v in data["per_suite"].items()]
    lines += ["", "## How episodes ended", *_termination_table({"all": data["overall"], **data["per_suite"]})]
    spatial = {k: v["instances"] for k, v in data["per_suite"].items() if v.get("instances")}
    if spatial:
        lines += ["", "## Which instance (Spatial suites)",
                  f"| suite | episodes | the other instance on the target | both instances disturbed "
                  f"(> {100 * DISTURBED_M:g} cm) |",
                  "|---|---|---|---|"]
        lines += [f"| {k} | {v['episodes']} | {v['wrong_instance']} | {v['both_disturbed']} |" for k, v in spatial.items()]
    lines += ["", "## Per task", HEADER] + [_row(k, v) for k, v in data["per_task"].items()]
    if len(data["per_condition"]) > len(data["per_suite"]):
        lines += ["", "## Per condition", HEADER] + [_row(k, v) for k, v in data["per_condition"].items()]
    return "\n".join(lines) + "\n", data


def write_report(records: list[dict], out_dir: Path, stem: str) -> tuple[Path, Path]:
    text, data = build_report(records)
    md, js = Path(out_dir) / f"{stem}.md", Path(out_dir) / f"{stem}.json"
    atomic_write(md, lambda p: p.write_text(text))
    atomic_write_json(js, data)
    return md, js


def rt_series(record: dict) -> tuple[np.ndarray, np.ndarray]:
    """A record's R_t trace against time (s): its stored D_t over its tolerance, one value per
    control step."""
    rt = deformation_ratio(np.asarray(record["deformation_trace"], np.float64), record["tau_o"])
    return np.arange(len(rt)) / CONTROL_FREQ, rt


def plot_traces(records: list[dict], out: Path) -> None:
    """R_t traces: successes within tolerance, successes beyond it, failures, coloured apart."""
    fig = Figure(figsize=(6, 3.5))
    ax = fig.subplots()
    for r in records:
        if not r["deformation_trace"]:  # nothing measured (a worker died)
            continue
        color = "tab:green" if r["dsr_success"] else ("tab:red" if r["success"] else "0.6")
        ax.plot(*rt_series(r), color=color, lw=0.8, alpha=0.8)
    ax.axhline(1.0, color="k", ls="--", lw=1)
    ax.plot([], [], color="tab:green", label="success, R_max <= 1, no tet collapsed")
    ax.plot([], [], color="tab:red", label="success beyond tolerance (R_max > 1 or a tet collapsed)")
    ax.plot([], [], color="0.6", label="failure")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("R_t = D_t / tau_o")
    ax.legend(fontsize=7)
    fig.tight_layout()
    atomic_write(out, lambda p: fig.savefig(p, dpi=120))


def plot_ood_curves(records: list[dict], id_records: list[dict], out: Path) -> None:
    """TSR and DSR against each OOD factor's value, with the ID point at the nominal value."""
    factors = {}
    for name, (key, value) in OOD_CONDITIONS.items():
        factors.setdefault(key, []).append((value, name))
    nominal = PhysicalFactors()
    fig = Figure(figsize=(4 * len(factors), 3.2))
    axes = fig.subplots(1, len(factors), squeeze=False)
    for ax, (key, pts) in zip(axes[0], factors.items()):
        xs, tsr, dsr = [], [], []
        for value, name in sorted(pts + [(getattr(nominal, key), "id")]):
            sel = id_records if name == "id" else [r for r in records if r["condition"] == name]
            if not sel:
                continue
            s = summarize(sel)
            xs.append(value)
            tsr.append(100 * s["tsr"])
            dsr.append(100 * s["dsr"])
        ax.plot(xs, tsr, "o-", label="TSR")
        ax.plot(xs, dsr, "s--", label="DSR")
        ax.set_xlabel(key)
        ax.set_ylabel("%")
        ax.set_ylim(-5, 105)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    atomic_write(out, lambda p: fig.savefig(p, dpi=120))
