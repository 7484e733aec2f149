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
    named = [{"receipt": {"stack": EPYC, "numerics": {"name": "x86-64-v3", "parts": list(N.PARTS), "pinned": True}}}]
    assert P.machine(named, {"cpu": "other"}) == "AMD EPYC (avx512_bf16 avx512f avx2 fma)"
    assert P.numerics(named, entry) == "x86-64-v3"
    assert N.numerics_of(stackless[0], entry) == "x86-64-v3:openblas" and N.numerics_of(stackless[0]) == "native"
    assert "AMD EPYC (its instruction set unrecorded)" in N.reproduction_note(stackless[0], EPYC, entry)


def _file(*stacks, **numerics):
    """A records file's (machine, numerics) as the reports read them: one record per stack."""
    recs = [{"receipt": {"stack": st, **({"numerics": numerics} if numerics else {})}} for st in stacks]
    return P.machine(recs), P.numerics(recs)


def test_a_table_of_files_from_two_machines_says_what_its_rows_may_compare():
    xeon = {"cpu": "Intel(R) Xeon(R) Processor"}
    epyc2 = {"cpu": "AMD EPYC", "cpu-isa": "AVX2 avx2 fma"}
    full = {"name": N.PINNED, "parts": list(N.PARTS), "pinned": True}
    before_vml = {**full, "parts": [p for p in N.PARTS if p != "vml"]}
    rates_only, records_too = "not their records", "their records compare"
    # Before the pins: two CPU models, or one model with other instruction sets, round differently.
    assert rates_only in P.crossing_note([_file(EPYC), _file(xeon)])
    assert rates_only in P.crossing_note([_file(EPYC), _file(epyc2)])
    assert P.crossing_note([_file(EPYC), _file(EPYC)]) is None
    text = "\n".join(provenance_lines([("a.jsonl", [{"receipt": {"stack": EPYC}}], None),
                                        ("b.jsonl", [{"receipt": {"stack": xeon}}], None)]))
    assert "| a.jsonl | AMD EPYC" in text and rates_only in text
    # A pre-pin AMD file reads as what that machine ran natively, the same as a sidecar saying so: one numerics.
    assert P.numerics([{"receipt": {"stack": EPYC}}]) == "x86-64-v3:openblas (before the pins)"
    note = P.crossing_note([_file(EPYC), ("AMD EPYC (per sidecar)", "x86-64-v3:openblas (per sidecar)")])
    assert "and numerics" not in note and "cross numerics" not in note  # (a sidecar names no flags: which EPYC is unknown)
    # Under today's full pins a record keeps its bits across vendors (the goldens): records compare, also
    # within one file resumed on another machine.
    assert records_too in P.crossing_note([_file(EPYC, xeon, **full)])
    assert P.crossing_note([_file(EPYC, **full), _file(epyc2, **full)]) is None  # one model; flags cannot matter
    assert P.crossing_note([_file(xeon, **full), _file(xeon, **full)]) is None
    # Today's name with a part released or a library loaded before the pins is not the full pins.
    released = {**full, "pinned": False, "released": ["onednn"]}
    assert _file(xeon, **released)[1] == "x86-64-v3 (not in effect)"
    assert rates_only in P.crossing_note([_file(EPYC, xeon, **released)])
    # The pins before vml kept a policy's bits on its vendor only; two numerics never compare records.
    assert rates_only in P.crossing_note([_file(EPYC, xeon, **before_vml)])
    assert "and numerics" in P.crossing_note([_file(EPYC, **full), _file(xeon, **before_vml)])
    # Where a file does not name its machine, nothing says the rows share one.
    assert rates_only in P.crossing_note([("unrecorded", "native (before the pins)"), _file(EPYC)[:1] + ("native",)])
    assert rates_only in P.crossing_note([("unrecorded", "native (before the pins)")] * 2)
    assert P.crossing_note([("unrecorded", "native (before the pins)")]) is None  # one file: nothing to compare


def test_the_committed_sidecars_name_every_file_that_does_not_name_its_machine():
    from mani_skill_softvt.evaluation.records import read_records

    for directory in (REPO_DIR / "campaign-data" / "results", REPO_DIR / "campaign-data" / "results" / "twins"):
        for path in sorted(directory.glob("*.jsonl")):
            first = read_records(path)[0]
            if not ((first["receipt"].get("stack") or {}).get("cpu")):
                entry = P.sidecar(path)
                assert entry and entry["cpu"] and entry["evidence"], path
