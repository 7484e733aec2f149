"""The findings page's rules (studies/findings.py) on synthetic records: the training-seed spread is
the yardstick, a claim is only as resolved as the records allow, twin suites pair on their seeds."""

import json

import pytest

from mani_skill_softvt.data.seeds import id_seed
from mani_skill_softvt.evaluation.records import record_hash
from mani_skill_softvt.studies import findings as F


def _rec(i, success, r_max, policy="vo-c-cpu", variant="vo-c,cpu", suite="object_soft", task=0):
    rec = {"suite": suite, "task_id": task, "condition": "id", "seed": id_seed(task, i),
           "policy": f"baselines/policies/{policy}.pt", "policy_sha256": f"{policy}-{suite}",
           "success": success, "dsr_success": success and r_max <= 1.0, "r_max": r_max,
           "termination": "success" if success else "timeout", "collapsed_steps": 0,
           "receipt": {"policy": f"diffusion_policy[{variant}]"}}
    rec["record_sha256"] = record_hash(rec)
    return rec


def _write(path, records):
    path.write_text("".join(json.dumps(r) + "\n" for r in records))


def test_a_claim_is_resolved_only_beyond_the_seed_spread_and_its_test():
    diff = {"pairs": 100, "difference": 0.10, "p_value": 0.001}
    assert F.resolved(diff, None) == "unknown"          # spread unmeasured: two policies are not told apart
    assert F.resolved(diff, 0.12) == "none"              # within the training noise
    assert F.resolved(diff, 0.05) == "a>b"
    assert F.resolved({**diff, "p_value": 0.2}, 0.05) == "none"
    assert F.resolved(diff, None, within_policy=True) == "a>b"  # one policy's own outcomes need no spread
    assert F.claim("x", "a>b", "a>b")["verdict"] == F.SUPPORTED
    assert F.claim("x", "a<b", "a>b")["verdict"] == F.CONTRADICTED
    assert F.claim("x", "none", "a>b")["verdict"] == F.UNRESOLVED
    assert F.claim("x", "none", "none")["verdict"] == F.SUPPORTED
    assert F.claim("x", "a>b", "none")["verdict"] == F.CONTRADICTED
    assert F.claim("x", "unknown", "none")["verdict"] == F.UNRESOLVED
    assert F.overall([F.claim("x", "a>b", "a>b"), F.claim("y", "missing", "a>b")]) == F.UNRESOLVED
    assert F.overall([F.claim("x", "a>b", "a>b"), F.claim("y", "a<b", "a>b")]) == F.CONTRADICTED


def test_seed_spread_from_two_training_seeds_then_rigid_against_soft(tmp_path):
    n = 100
    # Two training seeds of VO-C on Object-Soft: seed 1 loses 6 successes seed 0 had and wins 2.
    seed0 = [_rec(i, i < 80, 0.5) for i in range(n)]
    seed1 = [_rec(i, (i < 80 and i >= 6) or 80 <= i < 82, 0.5, "vo-c-cpu-seed1") for i in range(n)]
    # The rigid twin suite: the same seeds, 20 more successes (R_max of a rigid twin is ~0).
    rigid = [_rec(i, True, 1e-13, "object_rigid/vo-c-cpu", suite="object_rigid") for i in range(n)]
    _write(tmp_path / "object_soft_id_vo-c-cpu.jsonl", seed0)
    _write(tmp_path / "object_soft_id_vo-c-cpu-seed1.jsonl", seed1)
    _write(tmp_path / "object_rigid_id_vo-c-cpu.jsonl", rigid)
    result = F.main([str(tmp_path)])
    spread = result["seed_spread"]["spread"]
    assert spread["success"] == pytest.approx(0.04)  # |(6 - 2) / 100|
    f2 = result["finding2"]
    assert f2["pairs"]["vo-c"]["pairs"] == n and f2["pairs"]["vo-c"]["difference"] == pytest.approx(0.20)
    # +20 points, p < 0.05 and beyond the 4-point spread: a resolved cost of deformability, which
    # the paper's Diffusion Policy did not show.
    assert f2["claims"][0]["ours"] == "a>b" and f2["claims"][0]["verdict"] == F.CONTRADICTED
    assert f2["pairs"]["vt-c"] is None and f2["verdict"] == F.CONTRADICTED
    # Finding 1: no success left the tolerance, in either seed; one variant, so nothing to compare.
    assert [c["ours"] for c in result["finding1"]["claims"]] == ["none", "none", "missing"]
    assert result["finding1"]["verdict"] == F.UNRESOLVED
    assert result["finding4"]["verdict"] == F.UNRESOLVED  # no OOD records
    text = (tmp_path / "findings.md").read_text()
    assert "object_soft vo-c,cpu: seed 0 vs seed 1" in text and "**contradicted**" in text


def test_two_files_of_one_seed_are_refused(tmp_path):
    _write(tmp_path / "object_soft_id_vo-c-cpu.jsonl", [_rec(i, True, 0.5) for i in range(4)])
    _write(tmp_path / "object_soft_id_vo-c-cpu-copy.jsonl", [_rec(i, True, 0.5, "vo-c-cpu-copy") for i in range(4)])
    with pytest.raises(SystemExit):
        F.main([str(tmp_path)])
    with pytest.raises(SystemExit):
        F.main([str(tmp_path / "empty")])  # no records there: a clear error, not an empty page


def test_violations_that_depend_on_the_policy_and_a_misranking(tmp_path):
    n = 100
    vo = [_rec(i, i < 70, 0.5) for i in range(n)]                         # TSR 70, DSR 70
    vo1 = [_rec(i, i < 70 or i == 99, 0.5, "vo-c-cpu-seed1") for i in range(n)]  # one more success
    # VT-C succeeds more often but squeezes 30 of its 80 successes past tolerance: TSR ranks it
    # above VO-C, DSR below.
    vt = [_rec(i, i < 80, 1.5 if i < 30 else 0.5, "vt-c-cpu", "vt-c,cpu,rgb+depth") for i in range(n)]
    for name, recs in (("vo-c-cpu", vo), ("vo-c-cpu-seed1", vo1), ("vt-c-cpu", vt)):
        _write(tmp_path / f"object_soft_id_{name}.jsonl", recs)
    f1 = F.main([str(tmp_path)])["finding1"]
    assert [c["ours"] for c in f1["claims"]] == ["none", "none", "a>b", "a>b"]  # vo-c seeds 0/1, vt-c, differ
    assert f1["verdict"] == F.UNRESOLVED  # VO-C kept every success within tolerance
    (pair,) = f1["misrankings"].values()
    assert pair["tsr"]["difference"] == pytest.approx(-0.10) and pair["dsr"]["difference"] == pytest.approx(0.20)
