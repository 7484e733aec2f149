"""The pre-registered seed-level rule (evaluation/seed_level.py, docs/preregistration.md) and its command."""

import json
import math

import numpy as np
import pytest
from scipy import stats

from mani_skill_softvt.cli import compare as cli
from mani_skill_softvt.evaluation import seed_level as S
from mani_skill_softvt.evaluation.records import seal
from softvt_campaign.studies import rule_check


def test_pooled_variance_is_the_within_recipe_variance_with_its_degrees_of_freedom():
    var, df = S.pooled_variance([90.2, 73.0], [90.2, 89.8], [50.0])  # a lone seed adds nothing
    assert df == 2
    assert var == pytest.approx(((90.2 - 81.6) ** 2 * 2 + (0.2 ** 2) * 2) / 2)
    assert S.pooled_variance([1.0], [2.0]) == (None, 0)


def test_the_interval_is_students_t_on_the_seed_means():
    a, b = [70.0, 74.0, 78.0], [80.0, 84.0, 88.0]
    c = S.compare_seeds(a, b)
    se = math.sqrt(16.0 * (1 / 3 + 1 / 3))  # pooled variance 16, three seeds a side
    t = stats.t.ppf(0.975, 4)
    assert c.difference == pytest.approx(10.0) and c.df == 4 and c.se == pytest.approx(se)
    assert c.ci95 == pytest.approx((10 - t * se, 10 + t * se))
    # A family's variance (more recipes, more degrees of freedom) narrows it.
    wide = S.compare_seeds(a, b, (16.0, 12))
    assert wide.ci95[1] - wide.ci95[0] < c.ci95[1] - c.ci95[0]
    # An interaction of four recipes: its variance sums the four.
    inter = S.contrast([a, b, a, b], [1, -1, -1, 1])
    assert inter.difference == pytest.approx(0.0) and inter.se == pytest.approx(math.sqrt(16.0 * 4 / 3))


def test_one_seed_a_side_is_unresolved_whatever_the_difference():
    c = S.compare_seeds([50.0], [95.0])
    assert c.ci95 is None and S.verdict(c, paper=10.0) == S.UNRESOLVED


def _c(lo, hi, lo90=None, hi90=None):
    mid = (lo + hi) / 2
    return S.Comparison(mid, 3, 3, 1.0, 4, (lo, hi), (lo90 if lo90 is not None else lo + 1, hi90 if hi90 is not None else hi - 1))


def test_verdicts_follow_the_registered_rule():
    assert S.verdict(_c(2, 12), paper=10) == S.SUPPORTED  # excludes 0 on the paper's side
    assert S.verdict(_c(-12, -2), paper=-10) == S.SUPPORTED
    assert S.verdict(_c(-12, -2), paper=10) == S.CONTRADICTED  # sign claim: the other sign
    assert S.verdict(_c(-20, 25), paper=10) == S.UNRESOLVED  # holds 0 and the paper's effect
    # A claim of a size: an interval below the paper's effect that holds 0 contradicts the size.
    assert S.verdict(_c(-6, 4), paper=11.4, claim="size") == S.CONTRADICTED
    assert S.verdict(_c(-6, 4), paper=11.4, claim="sign") == S.UNRESOLVED  # absence of evidence
    assert S.verdict(_c(2, 6), paper=11.4, claim="size") == S.SUPPORTED
    assert S.size_note(_c(2, 6), 11.4) == "smaller than the paper's"
    # Equivalence: the 90 % interval within +-5 points, the margin fixed beforehand.
    assert S.verdict(_c(-5, 5, -4, 4), paper=0, claim="none") == S.SUPPORTED
    assert S.verdict(_c(-5, 5, -4, 4), paper=10, claim="sign") == S.EQUIVALENT
    assert S.verdict(_c(1, 9), paper=0, claim="none") == S.CONTRADICTED
    assert S.verdict(_c(-9, 9, -7, 7), paper=0, claim="none") == S.UNRESOLVED
    # A paper effect inside the margin and inside the interval: the interval decides nothing.
    assert S.verdict(_c(-3, 4, -2.2, 3.2), paper=2.0) == S.UNRESOLVED
    assert S.verdict(_c(-3, 1.5, -2.2, 1.0), paper=2.0, claim="size") == S.CONTRADICTED  # excludes its size
    assert S.verdict(_c(-3, 1.5, -2.2, 1.0), paper=2.0) == S.EQUIVALENT  # a sign claim: equivalent to none
    assert S.compare_seeds([50.0, 50.0], [60.0, 60.0]).ci95 is None  # seeds alike: no interval, not a certainty
    with pytest.raises(ValueError, match="claim='none'"):
        S.verdict(_c(1, 2), paper=0)


def test_a_finding_is_read_from_its_parts_and_an_unresolved_part_never_contradicts_it():
    assert S.finding_verdict([S.SUPPORTED, S.SUPPORTED]) == S.SUPPORTED
    assert S.finding_verdict([S.SUPPORTED, S.UNRESOLVED]) == "partly supported"
    assert S.finding_verdict([S.UNRESOLVED, S.UNRESOLVED]) == S.UNRESOLVED
    assert S.finding_verdict([S.CONTRADICTED, S.UNRESOLVED]) == S.CONTRADICTED
    assert S.finding_verdict([S.SUPPORTED, S.CONTRADICTED]) == "mixed"


def test_power_grows_with_seeds_and_a_five_point_difference_needs_many():
    mdd = [S.minimum_detectable(8.6, n) for n in (2, 3, 5, 10)]
    assert all(a > b for a, b in zip(mdd, mdd[1:]))
    # Large-sample check: (z_0.975 + z_0.8) * sd * sqrt(2 / n) at n = 200 seeds.
    assert S.minimum_detectable(8.6, 200) == pytest.approx(2.80 * 8.6 * math.sqrt(2 / 200), rel=0.01)
    n = S.seeds_needed(8.6, 5.0)
    assert S.minimum_detectable(8.6, n) <= 5.0 < S.minimum_detectable(8.6, n - 1)


def test_the_rule_calls_a_difference_about_five_percent_of_the_time_when_there_is_none():
    # 600 synthetic null comparisons at three seeds a side: the two-sided 95 % interval excludes 0 in
    # 5 % of them (binomial sd 0.9 %), the seed-score noise being normal plus binomial episodes.
    rates = rule_check.verdict_rates(3, 0.0, 8.6, 600, family=False, seed=1)
    called = rates[S.SUPPORTED] + rates[S.CONTRADICTED]
    assert 0.05 - 3 * 0.009 < called < 0.05 + 3 * 0.009
    # And a large true effect in the paper's direction is supported most of the time at five seeds.
    assert rule_check.verdict_rates(5, 25.0, 8.6, 200, family=True, seed=1)[S.SUPPORTED] > 0.9


def _records(path, outcomes, policy="p"):
    lines = []
    for i, (success, dsr) in enumerate(outcomes):
        rec = seal({"suite": "object_soft", "task_id": i % 2, "condition": "id", "seed": 50_000_000 + i, "policy": policy,
                    "success": success, "dsr_success": dsr, "termination": "success" if success else "timeout"})
        lines.append(json.dumps(rec))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_the_command_compares_seed_files_and_refuses_an_edited_one_in_one_line(tmp_path, capsys):
    rng = np.random.default_rng(0)
    files = {}
    for side, p in (("a", 0.5), ("b", 0.9)):
        for s in range(2):
            files.setdefault(side, []).append(_records(tmp_path / f"{side}{s}.jsonl",
                                                       [(bool(x), bool(x)) for x in rng.random(40) < p]))
    out = cli.main(["--a", *map(str, files["a"]), "--b", *map(str, files["b"]), "--paper", "10"])
    assert "40 shared episodes" in out and "tsr: A seeds" in out and "P(B beats A)" in out
    sub = cli.subset(cli.load_runs(files["a"]), 5)
    assert len(sub) == 10 and {k[1] for k in sub} == {0, 1}
    edited = files["a"][0].read_text().replace('"success": true', '"success": false', 1)
    files["a"][0].write_text(edited)
    with pytest.raises(SystemExit) as e:
        cli.main(["--a", *map(str, files["a"]), "--b", *map(str, files["b"])])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{files['a'][0]}:" in err and "record_sha256" in err


def test_seed_findings_score_each_seed_on_the_registered_subset_and_pool_the_family():
    from softvt_campaign.studies import seed_findings as SF

    def run(p, seed, rng):  # a complete ID run of one seed: 50 episodes a task, success with probability p
        return [{"suite": "object_soft", "task_id": t, "condition": "id", "seed": 50_000_000 + 1000 * t + i,
                 "policy": "campaign-data/policies/x.pt", "success": bool(ok), "dsr_success": bool(ok)}
                for t in range(10) for i, ok in enumerate(rng.random(50) < p)]

    rng = np.random.default_rng(0)
    policies = {("object_soft", "vo-c-cpu"): {0: run(0.5, 0, rng), 1: run(0.6, 1, rng)},
                ("object_soft", "vt-c-cpu"): {0: run(0.9, 0, rng), 1: run(0.95, 1, rng), 2: run(0.9, 2, rng)[:100]}}
    table = SF.seed_table(policies, "tsr")
    assert len(table[("object_soft", "vo-c-cpu")]) == 2 and len(table[("object_soft", "vt-c-cpu")]) == 2  # partial left out
    # Each score is on the first 25 episodes of each task: a multiple of 100 / 250 points.
    assert all(abs(x * 2.5 - round(x * 2.5)) < 1e-9 for v in table.values() for x in v)
    var, df = SF.family(table, ("object_soft",))
    assert df == 2 and var == pytest.approx(S.pooled_variance(*table.values())[0])
    judged = SF.claims(policies, {})
    touch = next(p for p in judged["3"] if p["claim"] == "VT-C - VO-C, TSR")
    assert touch["comparison"]["difference"] == pytest.approx(np.mean(table[("object_soft", "vt-c-cpu")])
                                                               - np.mean(table[("object_soft", "vo-c-cpu")]))
    assert all(p["verdict"] == "unresolved" and p["why"] == "not run" for p in judged["4"])


def test_seed_findings_judge_the_registered_spatial_claims_and_give_both_verdicts():
    from softvt_campaign.studies import seed_findings as SF

    def run(suite, p, rng):  # a complete ID run of one seed: 50 episodes a task
        return [{"suite": suite, "task_id": t, "condition": "id", "seed": 50_000_000 + 1000 * t + i,
                 "policy": "campaign-data/policies/x.pt", "success": bool(ok), "dsr_success": bool(ok)}
                for t in range(10) for i, ok in enumerate(rng.random(50) < p)]

    rng = np.random.default_rng(1)
    rates = {"object_soft": 0.8, "object_rigid": 0.6, "spatial_soft": 0.3, "spatial_rigid": 0.5}
    policies = {(suite, "vo-c-cpu"): {s: run(suite, p, rng) for s in range(3)} for suite, p in rates.items()}
    judged = SF.claims(policies, {}, {})
    table = SF.seed_table(policies, "tsr")
    mean = {suite: np.mean(table[(suite, "vo-c-cpu")]) for suite in rates}
    cost = next(p for p in judged["2"] if p["claim"].startswith("(Object-Rigid - Object-Soft)"))
    # The interaction is a contrast of four recipes, its variance pooled over all four suites (8 df).
    assert cost["axis"] == "spatial" and cost["seeds"] == [3, 3, 3, 3] and cost["comparison"]["df"] == 8
    assert cost["comparison"]["difference"] == pytest.approx((mean["object_rigid"] - mean["object_soft"])
                                                             - (mean["spatial_rigid"] - mean["spatial_soft"]))
    twins = next(p for p in judged["2"] if p["claim"].startswith("Spatial-Rigid VO-C"))
    assert twins["comparison"]["difference"] == pytest.approx(mean["spatial_rigid"] - mean["spatial_soft"])
    assert twins["comparison"]["df"] == 4  # the two Spatial suites' seeds
    # VT-C was never run on a Spatial suite: its parts are unresolved, never contradicted.
    assert all(p["verdict"] == "unresolved" and p["why"] == "not run" for p in judged["ID"] + judged["4"])
    _, data = SF.build(policies, {}, {})
    assert "ID" not in data["verdicts"] and set(data["verdicts_object_parts"]) <= set(data["verdicts"])
    # The paper's tables in its layout: each cell the seed mean beside the paper's; VT-C not run.
    text, _ = SF.build(policies, {}, {})
    ts = {o: SF.seed_table(policies, o) for o in SF.OUTCOME_NAMES}
    id_row = next(line for line in text.splitlines() if line.startswith("| VO-C | ") and "/ 37.4 |" in line)
    assert id_row.startswith(f"| VO-C | {np.mean(ts['tsr'][('object_soft', 'vo-c-cpu')]):.1f} (3 seeds) / 37.4 |")
    assert f"| {np.mean(ts['tsr'][('spatial_rigid', 'vo-c-cpu')]):.1f} (3 seeds) / 14.0 |" in text
    assert "| VT-C | not run / 40.0 | not run / 30.4 | not run / 33.0 | not run / 25.0 |" in text
    assert "| VO-C | not run / 29.2 (-8.2) |" in text  # no OOD run


def test_a_scene_reused_by_nine_conditions_counts_once_in_the_clustered_difference():
    rng = np.random.default_rng(0)
    a, b = rng.random(100) < 0.6, rng.random(100) < 0.4
    once = S.clustered_difference(a, b, range(100))
    # Independent pairs: the paired differences' standard error (up to statsmodels' small-sample factor).
    d = 100.0 * (b.astype(float) - a)
    assert once["difference"] == pytest.approx(d.mean())
    assert once["se"] == pytest.approx(d.std(ddof=1) / 10, rel=0.02)
    # Nine copies of each pair in its scene's cluster carry one scene's information, not nine.
    nine = S.clustered_difference(np.repeat(a, 9), np.repeat(b, 9), np.repeat(np.arange(100), 9))
    assert nine["difference"] == pytest.approx(once["difference"])
    assert nine["se"] == pytest.approx(once["se"], rel=0.02) and nine["clusters"] == 100
    assert S.clustered_difference([True, False], [True, False], [0, 1])["p_value"] == 1.0  # no pair differs
    assert S.clustered_difference([False, False], [True, True], [7, 7])["ci95"] is None  # one scene: no spread
    with pytest.raises(ValueError, match="2 A outcomes, 1 B outcomes"):
        S.clustered_difference([True, False], [True], [0, 1])


def test_pooled_ood_is_the_rate_over_the_nine_conditions_against_the_id_twins():
    from softvt_campaign.studies import seed_findings as SF

    def rec(task, seed, condition, ok, dsr):
        return {"suite": "spatial_soft", "task_id": task, "seed": seed, "condition": condition,
                "success": ok, "dsr_success": dsr}

    # Two initial states, each under nine conditions; the twin of state 0 succeeds, of state 1 fails.
    conds = sorted(SF.OOD_CONDITIONS)
    ood = [rec(0, 0, c, i < 6, i < 3) for i, c in enumerate(conds)] + [rec(0, 1, c, i < 3, False) for i, c in enumerate(conds)]
    twins = [rec(0, 0, "id", True, True), rec(0, 1, "id", False, False)]
    runs = {"names": {"vo-c": "v"}, "runs": {"v": (ood, twins)}}
    pooled = SF.pooled_ood({**runs, "twins_from": {"v": twins}}, "vo-c")
    # TSR 9 of 18 = 50 %, DSR 3 of 18; each OOD episode against its own twin: twins' rates 50 / 50 %.
    assert pooled == pytest.approx({"episodes": 18, "twins": 2, "tsr": 50.0, "tsr_change": 0.0, "dsr": 100 / 6, "dsr_change": 100 / 6 - 50})
    assert SF.ood_cell(pooled, "tsr") == "partial, 18 of 900: 50.0 (+0.0 on 2 of 100 twins)"  # short runs say so
    assert SF.ood_cell(SF.pooled_ood(runs, "vo-c"), "dsr").endswith(": 16.7 (-)")  # twins not run yet
    assert SF.pooled_ood(runs, "vt-c") is None and SF.ood_cell(None, "tsr") == "not run"
    assert SF.ood_cell(SF.pooled_ood({"error": "x.jsonl: a record was edited"}, "vo-c"), "tsr").startswith("error")
    # A VT-C run under way is shown in the table, never judged against VO-C's.
    half = {"names": {"vo-c": "v", "vt-c": "t"}, "runs": {"v": (ood, twins), "t": (ood[:9], twins)}}
    [claim] = SF.ood_claims(half, (("VT-C - VO-C, pooled OOD TSR", "tsr", 2.0),), {"tsr": (None, 0)})
    assert claim["verdict"] == "unresolved" and claim["comparison"] is None
    assert claim["why"] == "partial: VO-C 18 of 900, VT-C 9 of 900"
