"""The findings page's rules (studies/findings.py) on synthetic records: the training-seed spread is
the yardstick, only complete runs are judged, twin suites pair on their seeds."""

import json

import pytest

from mani_skill_softvt.data.seeds import id_seed
from mani_skill_softvt.evaluation.records import record_hash
from softvt_campaign.studies import findings as F


def _rec(i, success, r_max, policy="vo-c-cpu", variant="vo-c,cpu", suite="object_soft"):
    task, k = divmod(i, 50)  # 50 episodes a task: i in [0, 500) is the whole ID protocol
    rec = {"suite": suite, "task_id": task, "condition": "id", "seed": id_seed(task, k),
           "policy": f"campaign-data/policies/{policy}.pt", "policy_sha256": f"{policy}-{suite}",
           "success": success, "dsr_success": success and r_max <= 1.0, "r_max": r_max,
           "termination": "success" if success else "timeout", "collapsed_steps": 0,
           "receipt": {"policy": f"diffusion_policy[{variant}]"}}
    rec["record_sha256"] = record_hash(rec)
    return rec


def _write(path, records):
    path.write_text("".join(json.dumps(r) + "\n" for r in records))


def test_a_claim_is_judged_against_the_seed_spread_and_its_interval():
    diff = {"pairs": 500, "difference": 0.10, "difference_ci95": (0.06, 0.14), "p_value": 0.001}
    assert F.difference(diff, None) == "unknown"           # spread unmeasured: two policies are not told apart
    assert F.difference(diff, 0.12) == "inconclusive"      # within the training noise, but not shown equivalent
    assert F.difference(diff, 0.05) == "a>b"
    assert F.difference({**diff, "difference": -0.10, "difference_ci95": (-0.14, -0.06)}, 0.05) == "a<b"
    assert F.difference({**diff, "difference": 0.01, "difference_ci95": (-0.02, 0.04), "p_value": 0.6}, 0.05) == "equivalent"
    assert F.difference(None, 0.05) == "missing"
    assert F.claim("x", "a>b", "a>b")["verdict"] == F.SUPPORTED
    assert F.claim("x", "a<b", "a>b")["verdict"] == F.CONTRADICTED
    assert F.claim("x", "equivalent", "a>b")["verdict"] == F.CONTRADICTED  # no effect beyond the noise
    assert F.claim("x", "inconclusive", "a>b")["verdict"] == F.UNRESOLVED
    assert F.claim("x", "equivalent", "equivalent")["verdict"] == F.SUPPORTED
    assert F.claim("x", "a<b", "equivalent")["verdict"] == F.CONTRADICTED
    assert F.claim("x", "inconclusive", "equivalent")["verdict"] == F.UNRESOLVED  # a failed test is no support
    assert F.claim("x", "a<b", "differ")["verdict"] == F.SUPPORTED
    assert F.claim("x", "unknown", "differ")["verdict"] == F.UNRESOLVED
    assert F.overall([F.claim("x", "a>b", "a>b"), F.claim("y", "missing", "a>b")]) == F.UNRESOLVED
    assert F.overall([F.claim("x", "a>b", "a>b"), F.claim("y", "a<b", "a>b")]) == F.CONTRADICTED
    assert F.policy_seed("campaign-data/policies/object_rigid/vt-c-cpu-seed2.pt") == ("vt-c-cpu", 2)
    assert F.policy_seed("outputs/baselines/object_soft/vo-c-cpu/policy.pt") == ("vo-c-cpu", 0)


def test_seed_spread_from_two_training_seeds_then_rigid_against_soft(tmp_path):
    n = 500
    # Two training seeds of VO-C on Object-Soft: seed 1 loses 6 successes seed 0 had and wins 2.
    seed0 = [_rec(i, i < 400, 0.5) for i in range(n)]
    seed1 = [_rec(i, 6 <= i < 400 or 400 <= i < 402, 0.5, "vo-c-cpu-seed1") for i in range(n)]
    # The rigid twin suite: the same seeds, 100 more successes (R_max of a rigid twin is ~0).
    rigid = [_rec(i, True, 1e-13, "object_rigid/vo-c-cpu", suite="object_rigid") for i in range(n)]
    _write(tmp_path / "object_soft_id_vo-c-cpu.jsonl", seed0)
    _write(tmp_path / "object_soft_id_vo-c-cpu-seed1.jsonl", seed1)
    _write(tmp_path / "object_rigid_id_vo-c-cpu.jsonl", rigid)
    result = F.main([str(tmp_path)])
    spread = result["seed_spread"]["spread"]
    assert spread["success"] == pytest.approx(0.008)  # |(6 - 2) / 500|
    f2 = result["finding2"]
    assert f2["pairs"]["vo-c"]["pairs"] == n and f2["pairs"]["vo-c"]["difference"] == pytest.approx(0.20)
    # +20 points, p < 0.05 and beyond the spread: a cost of deformability, which the paper's
    # Diffusion Policy did not show.
    assert f2["claims"][0]["ours"] == "a>b" and f2["claims"][0]["verdict"] == F.CONTRADICTED
    assert f2["pairs"]["vt-c"] is None and len(f2["claims"]) == 1 and f2["verdict"] == F.CONTRADICTED
    # Beside the verdict, unjudged: the rigid policy against each soft seed (seed 1 carries 396).
    pairings = f2["claims"][0]["pairings"]
    assert sorted(pairings) == ["0/0", "0/1"] and [p["ours"] for p in pairings.values()] == ["a>b", "a>b"]
    assert pairings["0/1"]["comparison"]["difference"] == pytest.approx(104 / 500)
    # Finding 1: no success left the tolerance in either complete seed: contradicted.
    assert [c["verdict"] for c in result["finding1"]["claims"][:2]] == [F.CONTRADICTED] * 2
    assert result["finding1"]["claims"][2]["ours"] == "missing"  # no VT-C
    assert result["finding4"]["verdict"] == F.UNRESOLVED  # no OOD records
    text = (tmp_path / "findings.md").read_text()
    assert "object_soft vo-c-cpu: seed 0 vs seed 1" in text and "**contradicted**" in text
    assert "0/0: a>b +20.0; 0/1: a>b +20.8" in text


def test_a_partial_run_is_shown_but_not_judged(tmp_path):
    _write(tmp_path / "object_soft_id_vo-c-cpu.jsonl", [_rec(i, i < 400, 0.5) for i in range(500)])
    # Five episodes of a second seed: no spread from them (they would make it 0 and "resolve" everything).
    _write(tmp_path / "object_soft_id_vo-c-cpu-seed1.jsonl", [_rec(i, False, 0.5, "vo-c-cpu-seed1") for i in range(5)])
    # Two tasks of VO-B: shown, not compared.
    _write(tmp_path / "object_soft_id_vo-b-cpu.jsonl", [_rec(i, False, 0.5, "vo-b-cpu", "vo-b,cpu") for i in range(100)])
    result = F.main([str(tmp_path)])
    assert result["seed_spread"]["pairs"] == {} and result["seed_spread"]["spread"]["success"] is None
    verdicts = {c["claim"].split(":")[0]: c["verdict"] for c in result["finding1"]["claims"]}
    assert verdicts["vo-c-cpu seed 1 (vo-c,cpu)"] == F.UNRESOLVED  # 5 episodes: their count of 0 is not judged
    assert verdicts["vo-c-cpu seed 0 (vo-c,cpu)"] == F.CONTRADICTED
    f3 = result["finding3"]
    assert f3["rows"]["vo-b"] is None and f3["claims"][0]["ours"] == "missing"
    assert f3["claims"][0]["pairings"] == {}  # partial runs are not paired either


def test_violations_that_depend_on_the_policy_and_a_misranking(tmp_path):
    n = 500
    vo = [_rec(i, i < 350, 0.5) for i in range(n)]                                   # TSR 70, DSR 70
    vo1 = [_rec(i, i < 350 or i == 499, 0.5, "vo-c-cpu-seed1") for i in range(n)]    # one more success
    # VT-C succeeds more often but squeezes 150 of its 400 successes past tolerance: TSR ranks it
    # above VO-C, DSR below.
    vt = [_rec(i, i < 400, 1.5 if i < 150 else 0.5, "vt-c-cpu", "vt-c,cpu,rgb+depth") for i in range(n)]
    vt1 = [_rec(i, True, 0.5, "vt-c-cpu-seed1", "vt-c,cpu,rgb+depth") for i in range(5)]  # a partial run
    for name, recs in (("vo-c-cpu", vo), ("vo-c-cpu-seed1", vo1), ("vt-c-cpu", vt), ("vt-c-cpu-seed1", vt1)):
        _write(tmp_path / f"object_soft_id_{name}.jsonl", recs)
    f1 = F.main([str(tmp_path)])["finding1"]
    # VO-C seeds 0 and 1, VT-C seeds 0 and 1 (partial: not judged), then VT-C against VO-C.
    assert [c["verdict"] for c in f1["claims"]] == [F.CONTRADICTED, F.CONTRADICTED, F.SUPPORTED, F.UNRESOLVED,
                                                    F.SUPPORTED]
    assert f1["claims"][-1]["ours"] == "differ" and f1["verdict"] == F.CONTRADICTED  # VO-C kept every success within
    # VT-C's one complete seed against each of VO-C's two (not its partial seed 1), unjudged.
    assert {k: p["ours"] for k, p in f1["claims"][-1]["pairings"].items()} == {"0/0": "a>b", "0/1": "a>b"}
    (pair,) = f1["misrankings"].values()
    assert pair["tsr"]["difference"] == pytest.approx(-0.10) and pair["dsr"]["difference"] == pytest.approx(0.20)


def test_two_files_of_one_seed_are_refused(tmp_path):
    _write(tmp_path / "object_soft_id_vo-c-cpu.jsonl", [_rec(i, True, 0.5) for i in range(4)])
    # Another file of the same name (its hash differs), in another directory.
    _write(tmp_path / "object_soft_id_vo-c-cpu-copy.jsonl", [_rec(i, True, 0.5, "other/vo-c-cpu") for i in range(4)])
    with pytest.raises(SystemExit):
        F.main([str(tmp_path)])
    with pytest.raises(SystemExit):
        F.main([str(tmp_path / "empty")])  # no records there: a clear error, not an empty page
