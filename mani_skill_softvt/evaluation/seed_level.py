"""Comparing two training recipes over their training seeds: the pre-registered rule (docs/preregistration.md).

A Diffusion Policy recipe trained twice, identical but for the seed, scored 17.2 TSR points apart on
the same 500 episodes, while the protocol's own sampling interval is about +-4 points: a comparison
of two recipes is a comparison of their means over training seeds, with an interval over seeds.

- **Estimand**: the difference between two recipes' scores (TSR, DSR, or the share of episodes
  that succeed past tolerance, TSR - DSR; in points), each averaged over its training seeds, on one
  protocol's episodes (the same initial states for every seed of both).
- **Primary interval**: a seed's score is its rate on those episodes; the interval is Student's t on
  the seed means with the seed-to-seed variance pooled (:func:`pooled_variance`) over the seeds of
  both recipes, or over a family of recipes that share the training budget (more degrees of
  freedom, the same variance assumed). With one seed a side and no family variance there is no
  seed-level interval: the comparison is *unresolved* whatever the episodes say.
- **OOD comparisons** (one run per recipe and condition): the episode-level difference is
  clustered by initial state (an ID seed's scene is reused by every condition), with statsmodels'
  cluster-robust errors, and the seed-to-seed variance measured on the ID protocol is added
  (:func:`ood_interval`).
- **Verdicts** (:func:`verdict`) against what the paper claims: *supported* when the 95 % interval
  excludes 0 on the paper's side; *contradicted* when it excludes the paper's effect (its size for a
  size claim, its sign for a sign claim) without supporting it; *equivalent* when the 90 % interval
  lies within +-:data:`EQUIVALENCE_MARGIN` (two one-sided tests; the margin fixed in advance, not
  read off the noise) and the 95 % interval excludes the paper's effect; *unresolved* otherwise, and
  always when the 95 % interval holds both 0 and the paper's effect. Seeds that scored alike (zero
  variance) give no interval. A finding is read from its parts (:func:`finding_verdict`):
  an unresolved part never makes it contradicted.

rliable (Agarwal et al., NeurIPS 2021) adds, for reading and not for verdicts, each recipe's mean
score with a stratified bootstrap interval over its runs and tasks, and the probability that a run
of one recipe beats a run of the other (:func:`rliable_summary`); with three runs a bootstrap over
runs has ten distinct resamples and covers too little, which is why the verdicts use the t interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from .protocols import episode_key, scene_key

ALPHA = 0.05
EQUIVALENCE_MARGIN = 5.0  # points of TSR, DSR or TSR - DSR: fixed on 2026-12-02, before any record it judges
OUTCOMES = {"tsr": "success", "dsr": "dsr_success", "past_tolerance": "past_tolerance"}

SUPPORTED, CONTRADICTED, EQUIVALENT, UNRESOLVED = "supported", "contradicted", "equivalent", "unresolved"


def outcome_of(record: dict, outcome: str) -> bool:
    """An episode's outcome: ``tsr`` (task success), ``dsr`` (success within tolerance) or
    ``past_tolerance`` (a success past tolerance: counted in TSR, not in DSR)."""
    if outcome == "past_tolerance":
        return bool(record["success"]) and not bool(record["dsr_success"])
    return bool(record[OUTCOMES[outcome]])


def first_per_task(keys, n: int | None) -> set:
    """Of episode keys, the first ``n`` of each (suite, task, condition) by seed (None: all): the
    pre-registered subset is the first 25 ID episodes of each task."""
    if n is None:
        return set(keys)
    by_task: dict = {}
    for k in sorted(keys):
        by_task.setdefault(k[:3], []).append(k)
    return {k for ks in by_task.values() for k in ks[:n]}


def seed_scores(runs: list[list[dict]], outcome: str, episodes: set | None = None) -> np.ndarray:
    """Each run's (training seed's) score in points on ``episodes`` (default: those every run has)."""
    keys = [{episode_key(r): r for r in run} for run in runs]
    common = set.intersection(*(set(k) for k in keys)) if episodes is None else episodes
    if not common:
        raise ValueError("the runs share no episode: score them on the same protocol")
    return np.array([100.0 * np.mean([outcome_of(k[e], outcome) for e in common]) for k in keys])


def pooled_variance(*groups) -> tuple[float | None, int]:
    """(seed-to-seed variance in points^2, degrees of freedom) pooled over groups of seed scores, each
    the seeds of one recipe; groups of one seed add nothing. (None, 0) when no group has two."""
    ss, df = 0.0, 0
    for g in groups:
        g = np.asarray(g, dtype=float)
        if len(g) > 1:
            ss += float(((g - g.mean()) ** 2).sum())
            df += len(g) - 1
    return (ss / df if df else None), df


@dataclass(frozen=True)
class Comparison:
    """B - A in points over training seeds, with its seed-level intervals (None: not estimable)."""

    difference: float
    n_a: int
    n_b: int
    se: float | None
    df: int
    ci95: tuple[float, float] | None
    ci90: tuple[float, float] | None

    def to_dict(self) -> dict:
        return {"difference": self.difference, "n_a": self.n_a, "n_b": self.n_b, "se": self.se, "df": self.df,
                "ci95": self.ci95, "ci90": self.ci90}


def _intervals(diff: float, se: float | None, df: float) -> tuple[tuple | None, tuple | None]:
    if se is None or not df or not math.isfinite(se):
        return None, None
    t95, t90 = stats.t.ppf(1 - ALPHA / 2, df), stats.t.ppf(1 - ALPHA, df)
    return (diff - t95 * se, diff + t95 * se), (diff - t90 * se, diff + t90 * se)


def contrast(groups, weights, family: tuple[float | None, int] | None = None) -> Comparison:
    """sum_k weights[k] * mean(groups[k]) over recipes' seed scores (points), with its seed-level
    intervals: B - A is ``contrast([a, b], [-1, 1])``; an interaction, four groups. ``family``: a
    (variance, df) pooled over more recipes (:func:`pooled_variance`); default, the groups' own seeds."""
    groups = [np.asarray(g, dtype=float) for g in groups]
    var, df = family if family is not None else pooled_variance(*groups)
    if var is not None and var <= 0:
        var = None  # seeds that scored alike measure no noise: no interval rather than a zero-width one
    value = float(sum(w * g.mean() for w, g in zip(weights, groups)))
    se = None if var is None else math.sqrt(var * sum(w * w / len(g) for w, g in zip(weights, groups)))
    ci95, ci90 = _intervals(value, se, df)
    return Comparison(value, len(groups[0]), len(groups[-1]), se, df, ci95, ci90)


def compare_seeds(a, b, family: tuple[float | None, int] | None = None) -> Comparison:
    """B - A from their seed scores (points); ``family`` as in :func:`contrast`."""
    return contrast([a, b], [-1.0, 1.0], family)


def clustered_difference(a, b, clusters) -> dict:
    """Mean of B - A over pairs of outcomes (points), with statsmodels' cluster-robust standard
    error and a normal 95 % interval and p-value. The pairs of one cluster (an initial state
    the nine OOD conditions reuse, or one ID twin paired with nine OOD episodes) are not independent
    draws: an exact McNemar over them counts each scene up to nine times."""
    import statsmodels.api as sm

    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape or len(clusters) != len(a) or not len(a):
        raise ValueError(f"clustered_difference: {len(a)} A outcomes, {len(b)} B outcomes, {len(clusters)} clusters")
    label: dict = {}
    groups = np.array([label.setdefault(c, len(label)) for c in clusters] * 2)
    if len(label) < 2:  # one cluster: its errors estimate no spread between clusters
        return {"difference": 100.0 * float(b.mean() - a.mean()), "se": None, "ci95": None, "p_value": None,
                "pairs": len(a), "clusters": len(label)}
    x = sm.add_constant(np.r_[np.zeros(len(a)), np.ones(len(b))])
    with np.errstate(invalid="ignore"):  # no spread: a variance of -0.0 (rounding) has no square root
        fit = sm.OLS(100.0 * np.r_[a, b], x).fit(cov_type="cluster", cov_kwds={"groups": groups})
        diff, se = float(fit.params[1]), float(fit.bse[1])
    if not se > 0:  # every pair alike, or every pair differing the same way: no spread to test against
        se, p, ci = 0.0, (1.0 if diff == 0 else 0.0), (diff, diff)
    else:
        p = float(2 * stats.norm.sf(abs(diff) / se))
        z = stats.norm.ppf(1 - ALPHA / 2)
        ci = (diff - z * se, diff + z * se)
    return {"difference": diff, "se": se, "ci95": ci, "p_value": p, "pairs": len(a), "clusters": len(label)}


def ood_interval(a: list[dict], b: list[dict], outcome: str, seed_variance: tuple[float | None, int],
                 n_a: int = 1, n_b: int = 1) -> Comparison:
    """B - A on OOD episodes (one run each), clustered by initial state (the ID seed every condition
    reuses), plus the seed-to-seed variance measured on the ID protocol. Degrees of freedom: the
    seed variance's (the smaller, and the one that dominates)."""
    ka, kb = {episode_key(r): r for r in a}, {episode_key(r): r for r in b}
    common = sorted(set(ka) & set(kb))
    if not common:
        raise ValueError("the OOD runs share no episode")
    c = clustered_difference([outcome_of(ka[e], outcome) for e in common], [outcome_of(kb[e], outcome) for e in common],
                             [scene_key(ka[e]) for e in common])
    diff, se_episodes = c["difference"], (math.nan if c["se"] is None else c["se"])  # nan: no interval
    var, df = seed_variance
    if var is None:
        return Comparison(diff, n_a, n_b, None, 0, None, None)
    se = math.sqrt(se_episodes ** 2 + var * (1 / n_a + 1 / n_b))
    ci95, ci90 = _intervals(diff, se, df)
    return Comparison(diff, n_a, n_b, se, df, ci95, ci90)


def verdict(c: Comparison, paper: float, claim: str = "sign", margin: float = EQUIVALENCE_MARGIN) -> str:
    """What ``c`` says of the paper's claim: ``claim`` "sign" (B - A has the sign of ``paper``),
    "size" (B - A is about ``paper``, a difference of that size) or "none" (no difference; ``paper``
    ignored). See the module docstring."""
    if c.ci95 is None:
        return UNRESOLVED
    lo, hi = c.ci95
    equivalent = c.ci90 is not None and -margin < c.ci90[0] and c.ci90[1] < margin
    if claim == "none":
        if lo > 0 or hi < 0:
            return CONTRADICTED
        return SUPPORTED if equivalent else UNRESOLVED
    if paper == 0:
        raise ValueError("a claimed difference of 0 is claim='none'")
    side = 1.0 if paper > 0 else -1.0
    lo_s, hi_s = sorted((side * lo, side * hi))  # on the paper's side: positive supports
    if lo_s > 0:
        return SUPPORTED
    excluded = hi_s < (abs(paper) if claim == "size" else 0.0)
    if excluded:
        return CONTRADICTED
    if lo <= paper <= hi:  # the interval holds both 0 and the paper's effect: it decides nothing
        return UNRESOLVED
    return EQUIVALENT if equivalent else UNRESOLVED


def size_note(c: Comparison, paper: float) -> str | None:
    """For a supported size claim: whether ours is smaller or larger than the paper's effect."""
    if c.ci95 is None:
        return None
    lo, hi = sorted(x * (1 if paper > 0 else -1) for x in c.ci95)
    if hi < abs(paper):
        return "smaller than the paper's"
    if lo > abs(paper):
        return "larger than the paper's"
    return None


def finding_verdict(parts: list[str]) -> str:
    """A finding from its claims' verdicts: supported when every claim is (an equivalence counts for a
    claim of no difference, as :func:`verdict` returns it), contradicted when one is and none is
    supported, ``mixed`` when some are each, ``partly supported`` when some are and the rest are
    unresolved, unresolved otherwise. An unresolved part never makes a finding contradicted."""
    s = parts.count(SUPPORTED)
    c = parts.count(CONTRADICTED)
    if parts and s == len(parts):
        return SUPPORTED
    if s and c:
        return "mixed"
    if c:
        return CONTRADICTED
    if s:
        return "partly supported"
    return UNRESOLVED


def per_task_scores(runs: list[list[dict]], outcome: str) -> np.ndarray:
    """(runs, tasks) scores in [0, 1]: what rliable aggregates."""
    tasks = sorted({int(r["task_id"]) for run in runs for r in run})
    return np.array([[np.mean([outcome_of(r, outcome) for r in run if int(r["task_id"]) == t]) for t in tasks]
                     for run in runs])


def rliable_summary(a_runs: list[list[dict]], b_runs: list[list[dict]], outcome: str, reps: int = 2000,
                    seed: int = 0) -> dict:
    """rliable's mean score of each recipe with its stratified-bootstrap 95 % interval over runs and
    tasks, and the probability of improvement P(a run of B beats a run of A) with its interval."""
    from rliable import library as rly
    from rliable import metrics

    scores = {"a": per_task_scores(a_runs, outcome), "b": per_task_scores(b_runs, outcome)}
    np.random.seed(seed)  # rliable draws from NumPy's global generator
    point, ci = rly.get_interval_estimates(scores, lambda x: np.array([metrics.aggregate_mean(x)]), reps=reps)
    pair = {"b,a": (scores["b"], scores["a"])}
    p_point, p_ci = rly.get_interval_estimates(pair, metrics.probability_of_improvement, reps=reps)
    return {"mean_a": 100 * float(point["a"][0]), "mean_a_ci95": (100 * float(ci["a"][0, 0]), 100 * float(ci["a"][1, 0])),
            "mean_b": 100 * float(point["b"][0]), "mean_b_ci95": (100 * float(ci["b"][0, 0]), 100 * float(ci["b"][1, 0])),
            "p_improvement": float(p_point["b,a"]),
            "p_improvement_ci95": (float(np.ravel(p_ci["b,a"])[0]), float(np.ravel(p_ci["b,a"])[1]))}


def minimum_detectable(sd: float, n: int, df: int | None = None, power: float = 0.8) -> float:
    """The smallest true difference (points) that ``n`` seeds a side detect with ``power`` at the
    5 % level, for a seed-to-seed standard deviation ``sd`` (t with ``df``, default 2n - 2)."""
    df = df if df is not None else 2 * n - 2
    if df < 1:
        return math.inf
    return float((stats.t.ppf(1 - ALPHA / 2, df) + stats.t.ppf(power, df)) * sd * math.sqrt(2 / n))


def seeds_needed(sd: float, difference: float, power: float = 0.8, max_n: int = 200) -> int | None:
    """Seeds a side for :func:`minimum_detectable` to reach ``difference`` (None beyond ``max_n``)."""
    return next((n for n in range(2, max_n + 1) if minimum_detectable(sd, n) <= difference), None)
