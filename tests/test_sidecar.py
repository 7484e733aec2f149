"""The provenance sidecar: what is known of records that do not name their machine (evaluation/sidecar.py)."""

import json

from mani_skill_softvt.provenance import numerics as N
from mani_skill_softvt.evaluation import sidecar as P
from mani_skill_softvt.paths import REPO_DIR
from softvt_campaign.studies.results import provenance_lines

EPYC = {"cpu": "AMD EPYC", "cpu-isa": "AVX512 avx512_bf16 avx512f avx2 fma"}


def test_a_sidecar_entry_fills_in_what_a_file_does_not_say(tmp_path):
    (tmp_path / "provenance.json").write_text(json.dumps(
        {"files": {"old.jsonl": {"cpu": "AMD EPYC", "numerics": "x86-64-v3:openblas", "evidence": "notes"}}}))
    entry = P.sidecar(tmp_path / "old.jsonl")
    assert entry["cpu"] == "AMD EPYC" and P.sidecar(tmp_path / "other.jsonl") is None
    assert P.sidecar(tmp_path / "elsewhere" / "old.jsonl") is None
    stackless = [{"receipt": {}}]
    assert P.machine(stackless, entry) == "AMD EPYC (per sidecar)" and P.machine(stackless) == "unrecorded"
    assert P.numerics(stackless, entry) == "x86-64-v3:openblas (per sidecar)"
    assert P.numerics(stackless) == "native (before the pins)"
    # A record's own stack wins over the sidecar.
    named = [{"receipt": {"stack": EPYC, "numerics": {"name": "x86-64-v3", "parts": list(N.PARTS)}}}]
    assert P.machine(named, {"cpu": "other"}) == "AMD EPYC (avx512_bf16 avx512f avx2 fma)"
    assert P.numerics(named, entry) == "x86-64-v3"
    assert N.numerics_of(stackless[0], entry) == "x86-64-v3:openblas" and N.numerics_of(stackless[0]) == "native"
    assert "AMD EPYC (its instruction set unrecorded)" in N.reproduction_note(stackless[0], EPYC, entry)


def test_a_table_of_files_from_two_machines_says_what_its_rows_may_compare():
    xeon = [{"receipt": {"stack": {"cpu": "Intel(R) Xeon(R) Processor"}}}]
    epyc = [{"receipt": {"stack": EPYC}}]
    text = "\n".join(provenance_lines([("a.jsonl", epyc, None), ("b.jsonl", xeon, None)]))
    assert "cross machines" in text and "not their records" in text and "| a.jsonl | AMD EPYC" in text
    assert "cross" not in "\n".join(provenance_lines([("a.jsonl", epyc, None), ("c.jsonl", epyc, None)]))
    # Under today's full pins a record keeps its bits across vendors (the goldens): records compare.
    pinned = {"name": N.PINNED, "parts": list(N.PARTS)}
    full = [{"receipt": {"stack": s, "numerics": pinned}} for s in (EPYC, {"cpu": "Intel(R) Xeon(R) Processor"})]
    note = P.crossing_note([(P.machine(full), P.numerics(full))])  # one file resumed on the other vendor
    assert "cross machines (AMD EPYC; Intel(R) Xeon(R) Processor)" in note and "their records compare" in note
    # The pins before vml kept a policy's bits on its vendor only; two numerics never compare records.
    before = [{"receipt": {"stack": s, "numerics": {**pinned, "parts": [p for p in N.PARTS if p != "vml"]}}}
              for s in (EPYC, {"cpu": "Intel(R) Xeon(R) Processor"})]
    assert "not their records" in P.crossing_note([(P.machine(before), P.numerics(before))])
    assert "and numerics (x86-64-v3; " in P.crossing_note([(P.machine(full), P.numerics(full)), (P.machine(before), P.numerics(before))])


def test_the_committed_sidecars_name_every_file_that_does_not_name_its_machine():
    from mani_skill_softvt.evaluation.records import read_records

    for directory in (REPO_DIR / "campaign-data" / "results", REPO_DIR / "campaign-data" / "results" / "twins"):
        for path in sorted(directory.glob("*.jsonl")):
            first = read_records(path)[0]
            if not ((first["receipt"].get("stack") or {}).get("cpu")):
                entry = P.sidecar(path)
                assert entry and entry["cpu"] and entry["evidence"], path
