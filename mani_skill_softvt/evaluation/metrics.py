"""Benchmark metrics as pure functions (paper section 4.2).

R_t = D_t / tau_o, R_max = max_t R_t; an episode counts for the Deformation-aware Success Rate
when the task succeeded, R_max <= 1 and no tet collapsed. TSR = mean(T), DSR = mean(T * [R_max <= 1]
* [no collapse]).

The collapse is one addition to the paper's criterion: an episode in which a tet of a soft object
in the scene collapsed or inverted (``collapsed_steps`` > 0) violated its tolerance whatever R_max
says. The mesh then no longer represents the local compression, so D_t cannot certify that the
object was handled gently.
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
from .protocols import episode_key, scene_key


def deformation_ratio(d_t, tau_o: float):
    """R_t = D_t / tau_o, on a scalar D_t or an array of them."""
    if not tau_o > 0:
        raise ValueError(f"deformation tolerance tau_o must be positive, got {tau_o}")
    return np.asarray(d_t, dtype=np.float64) / tau_o if np.ndim(d_t) else float(d_t) / float(tau_o)


def r_max(r_trace) -> float:
    """R_max: the peak of a deformation-ratio trace R_t (0 for an empty trace)."""
    r_trace = np.asarray(r_trace, dtype=np.float64)
    return float(r_trace.max()) if r_trace.size else 0.0


def dsr_success(task_success: bool, r_max: float, collapsed: bool = False) -> bool:
    """The episode counts for DSR: task success, R_max <= 1 and no collapsed tet."""
    return bool(task_success) and float(r_max) <= 1.0 and not collapsed


def collapsed(record: dict) -> bool:
    """A tet of the record's scene collapsed or inverted during the episode (``collapsed_steps``
    is None where nothing was measured: a worker died)."""
    return bool(record["collapsed_steps"])


def wilson_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """95 % Wilson score interval of a binomial proportion (the default z)."""
    if n == 0:
        return (0.0, 1.0)
    if not 0 <= successes <= n:
        raise ValueError(f"successes must lie in [0, n], got {successes} of {n}")
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def percent(x: float | None, digits: int = 1) -> str:
    """A rate as a percentage for reports; "-" for none."""
    return "-" if x is None else f"{100 * x:.{digits}f}"


def percent_ci(x: float, ci: tuple[float, float] | None, digits: int = 1) -> str:
    """``x [lo, hi]`` in percent; "- (no successes)" where the interval is undefined (None)."""
    return "- (no successes)" if ci is None else f"{percent(x, digits)} [{percent(ci[0], digits)}, {percent(ci[1], digits)}]"


def tolerance_violated(record: dict) -> bool:
    """The episode deformed its object beyond tolerance: R_max > 1, a tet collapsed
    (:func:`collapsed`), or the FEM blew up (``sim_unstable``, whatever R_max was before)."""
    if record.get("termination") == "sim_unstable" or collapsed(record):
        return True
    return record.get("r_max") is not None and float(record["r_max"]) > 1.0


# An instance whose centroid ended more than this far from where its episode began was disturbed: a
# resting object sleeps and drifts far less (docs/physics.md), a push or a grasp moves it further.
DISTURBED_M = 0.02


def instance_outcomes(records: list[dict]) -> dict | None:
    """In Spatial records (which name ``instructed_instance``): episodes that ended with the other
    instance on the target (``wrong_instance``: carried there instead of, or beside, the instructed
    one) and episodes in which both instances were disturbed (moved by more than :data:`DISTURBED_M`).
    None for records without them (Object suites, or records made before they were kept)."""
    spatial = [r for r in records if "instructed_instance" in r and r.get("instance_displacement")]
    if not spatial:
        return None
    return {"episodes": len(spatial), "wrong_instance": sum(bool(r["other_in_target"]) for r in spatial),
            "both_disturbed": sum(all(d > DISTURBED_M for d in r["instance_displacement"].values()) for r in spatial)}


def carried_instance(record: dict) -> str | None:
    """Which instance a Spatial episode carried to the target: ``"instructed"`` (a success, the other
    instance not on the target), ``"other"`` (the other on the target, no success), or None (neither,
    both, or an episode that measured nothing, e.g. a dead worker's). A success needs the instance at
    rest and released on the target; ``other_in_target`` only that the other lies in the target region."""
    ok, other = bool(record.get("success")), bool(record.get("other_in_target"))
    return "instructed" if ok and not other else "other" if other and not ok else None


def side_swap_agreement(id_records: list[dict], swap_records: list[dict]) -> dict:
    """A policy's side-swap episodes against its ID episodes of the same task and seed (the same
    scene, the other instance instructed): which instance it carried to the target in each
    (:func:`carried_instance`).

    ``followed``: it carried the instructed instance in both (it read the instruction);
    ``same_instance``: it carried the same instance in both, the ID's instructed one or its other
    (it ignored the instruction: a blind policy's swap success is its ID run's wrong instance); the
    two are exclusive, and the pairs in neither carried nothing (or both) in at least one episode.
    ``pairs``: the pairs compared, ``unpaired``: episodes only one file holds."""
    def by_seed(records, name):
        out = {scene_key(r): r for r in records}
        if len(out) < len(records):
            raise ValueError(f"side_swap_agreement: an episode (task, seed) appears twice in the {name} records")
        return out

    ids, swaps = by_seed(id_records, "ID"), by_seed(swap_records, "side-swap")
    common = sorted(set(ids) & set(swaps))
    for k in common:
        sides = {ids[k].get("instructed_instance"), swaps[k].get("instructed_instance")}
        if len(sides) == 1 and None not in sides:  # a dead worker's record names no instance
            raise ValueError(f"task {k[0]} seed {k[1]}: the two episodes instruct the same instance; give the ID "
                             "records first and the side-swap records second")
    carried = [(carried_instance(ids[k]), carried_instance(swaps[k])) for k in common]
    return {"pairs": len(common), "unpaired": len(ids) + len(swaps) - 2 * len(common),
            "followed": sum(c == ("instructed", "instructed") for c in carried),
            "same_instance": sum(c in (("instructed", "other"), ("other", "instructed")) for c in carried)}


def summarize(records: list[dict]) -> dict:
    """TSR, DSR, their gap and the gap's share of successes, with Wilson intervals; how the
    episodes ended (``terminations``) and how many violated their tolerance.

    ``records`` need ``success`` and ``r_max`` (``r_max`` None: not measured, e.g. a worker
    died) and ``dsr_success`` (:func:`dsr_success`, as the episode was scored).
    """
    n = len(records)
    t = sum(bool(r["success"]) for r in records)
    d = sum(bool(r["dsr_success"]) for r in records)
    if d > t:
        raise AssertionError("DSR exceeds TSR: a deformation-aware success must be a task success")
    tsr, dsr = (t / n, d / n) if n else (0.0, 0.0)
    measured = [r["r_max"] for r in records if r.get("r_max") is not None]
    terminations = defaultdict(int)
    for r in records:
        terminations[r.get("termination") or "unrecorded"] += 1
    return {
        "episodes": n, "task_successes": t, "dsr_successes": d,
        "tsr": tsr, "tsr_ci95": wilson_interval(t, n), "dsr": dsr, "dsr_ci95": wilson_interval(d, n),
        "gap": tsr - dsr, "gap_ci95": wilson_interval(t - d, n),
        "gap_share_of_successes": (t - d) / t if t else 0.0,
        "gap_share_ci95": wilson_interval(t - d, t) if t else None,  # None: no successes to share
        "r_max_median": float(np.median(measured)) if measured else float("nan"),
        "tolerance_violations": sum(tolerance_violated(r) for r in records),
        "collapses": sum(collapsed(r) for r in records),
        "terminations": dict(sorted(terminations.items())),
        "instances": instance_outcomes(records),
    }


def group_summaries(records: list[dict], keys: tuple[str, ...]) -> dict:
    """:func:`summarize` per value of ``keys`` (e.g. ("suite",), ("suite", "task_id"), ("condition",))."""
    groups = defaultdict(list)
    for r in records:
        groups[tuple(r[k] for k in keys)].append(r)
    return {k: summarize(v) for k, v in sorted(groups.items(), key=lambda kv: tuple(map(str, kv[0])))}


def rescore_record(record: dict, tau_new: float) -> dict:
    """The record scored against another tolerance, from its stored D_t trace (no rollout).

    Success and termination are kept (a blown-up FEM stays a failure); a record with nothing
    measured (``r_max`` None) keeps ``r_max`` None."""
    if record.get("r_max") is None:
        return dict(record, tau_o=tau_new)
    peak = r_max(deformation_ratio(record["deformation_trace"], tau_new))
    out = dict(record, tau_o=tau_new, r_max=peak)
    out["dsr_success"] = dsr_success(record["success"], peak, collapsed(record))
    return out


def mcnemar_exact_p(only_a: int, only_b: int) -> float:
    """Two-sided exact McNemar p-value: the chance, if A and B were equally good, of discordant
    pairs splitting at least as unevenly as ``only_a`` : ``only_b`` (a binomial test at 1/2)."""
    n, k = only_a + only_b, min(only_a, only_b)
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2 ** n
    return min(1.0, 2 * tail)


def paired_difference_ci(both: int, only_a: int, only_b: int, neither: int,
                         z: float = 1.959963984540054) -> tuple[float, float]:
    """95 % interval of the paired difference of rates (only_a - only_b) / pairs: Newcombe's hybrid
    score interval for paired data (his method 10, Stat. Med. 1998): each policy's Wilson interval,
    joined with the correlation of the pairs. It stays inside [-1, 1] and behaves at the small
    discordant counts where the Wald interval collapses. No pairs: (0, 0)."""
    n = both + only_a + only_b + neither
    if n == 0:
        return (0.0, 0.0)
    p1, p2 = (both + only_a) / n, (both + only_b) / n
    l1, u1 = wilson_interval(both + only_a, n, z)
    l2, u2 = wilson_interval(both + only_b, n, z)
    den = (both + only_a) * (only_b + neither) * (both + only_b) * (only_a + neither)
    phi = (both * neither - only_a * only_b) / math.sqrt(den) if den else 0.0
    d = p1 - p2
    lower = math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    upper = math.sqrt(max(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2))
    return (d - lower, d + upper)


def paired_comparison(a: list[dict], b: list[dict], outcome: str = "success", key=episode_key) -> dict:
    """Two policies on the same episodes (matched by ``key``: suite, task, condition and seed; a
    suite and its twin pair on ``protocols.seed_key``): how many
    pairs both / only A / only B / neither got ``outcome`` (``success`` or ``dsr_success``), the difference of rates with its exact McNemar p-value. Pairing
    removes the seed-to-seed spread that two independent intervals carry; episodes only one
    policy ran are left out and counted."""
    a_by, b_by = {key(r): r for r in a}, {key(r): r for r in b}
    if len(a_by) < len(a) or len(b_by) < len(b):
        raise ValueError("an episode appears twice in one policy's records (the same suite, task, condition and "
                         "seed; or, paired across twin suites, the same task, condition and seed)")
    common = sorted(set(a_by) & set(b_by))
    counts = {"both": 0, "only_a": 0, "only_b": 0, "neither": 0}
    for k in common:
        ga, gb = bool(a_by[k][outcome]), bool(b_by[k][outcome])
        counts["both" if ga and gb else "only_a" if ga else "only_b" if gb else "neither"] += 1
    n = len(common)
    return {"pairs": n, **counts, "unpaired": len(a_by) + len(b_by) - 2 * n,
            "difference": (counts["only_a"] - counts["only_b"]) / n if n else 0.0,
            "difference_ci95": paired_difference_ci(counts["both"], counts["only_a"], counts["only_b"], counts["neither"]),
            "p_value": mcnemar_exact_p(counts["only_a"], counts["only_b"])}
