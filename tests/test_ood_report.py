"""The OOD study (studies/ood_results.py) on synthetic records: ID twins, paired changes, the stiffness table."""

import json

import pytest

from softvt_campaign.studies import ood_results as O
from mani_skill_softvt.data.seeds import id_seed
from mani_skill_softvt.evaluation.records import record_hash
from mani_skill_softvt.tasks.suites import OOD_CONDITIONS


def _rec(task, i, condition, success, r_max, variant="vo-c,cpu", suite="object_soft"):
    rec = {"suite": suite, "task_id": task, "condition": condition, "seed": id_seed(task, i),
           "policy": f"campaign-data/policies/{variant.split(',')[0]}-cpu.pt", "success": success,
           "dsr_success": success and r_max <= 1.0, "r_max": r_max, "termination": "success" if success else "timeout",
           "collapsed_steps": 0, "receipt": {"policy": f"diffusion_policy[{variant}]"}}
    rec["record_sha256"] = record_hash(rec)
    return rec


def test_ood_is_read_against_its_id_twins_paired_and_by_stiffness():
    # ID: 50 episodes of task 0, all successes within tolerance at R_max 0.5 (seeds 0-9 are the twins).
    id_records = [_rec(0, i, "id", True, 0.5) for i in range(50)]
    # OOD: softening (E x0.5) keeps every success but squeezes past tolerance; dim light fails 6 of 10.
    ood = [_rec(0, i, "youngs_modulus_x0.5", True, 1.6) for i in range(10)]
    ood += [_rec(0, i, "light_67.5", i >= 6, 0.4) for i in range(10)]
    result = O.analyse({"vo-c,cpu": (ood, id_records)})
    v = result["variants"]["vo-c,cpu"]
    assert v["id_twins"]["episodes"] == 10 and v["id"]["episodes"] == 50
    assert v["pooled"]["tsr"] == pytest.approx(14 / 20) and v["pooled"]["dsr"] == pytest.approx(4 / 20)
    # Paired on the twins: 6 OOD episodes lost the success the ID twin had, none the other way.
    assert (v["paired_tsr"]["only_a"], v["paired_tsr"]["only_b"], v["paired_tsr"]["pairs"]) == (0, 6, 20)
    assert v["paired_tsr"]["difference"] == pytest.approx(-0.3)
    assert v["paired_dsr"]["only_b"] == 16 and v["paired_dsr"]["p_value"] < 1e-4
    # Pooled, the 20 pairs are 10 scenes (each twin serves two conditions): clustered by initial state.
    clustered = v["paired_tsr"]["clustered"]
    assert (clustered["pairs"], clustered["clusters"]) == (20, 10) and clustered["difference"] == pytest.approx(-30.0)
    # Stiffness: x1.0 is the twins, x0.5 the softened episodes; no x0.8 / x2.0 ran.
    assert set(v["stiffness"]) == {0.5, 1.0}
    assert v["stiffness"][1.0]["r_max"]["median"] == pytest.approx(0.5) and v["stiffness"][1.0]["episodes"] == 10
    assert v["stiffness"][0.5]["tsr"] == 1.0 and v["stiffness"][0.5]["dsr"] == 0.0
    text = O.build(result)
    assert "| youngs_modulus_x0.5 | 100 / 0 (10) | 33 / 32 |" in text  # ours beside the paper's DP
    assert "| x0.5 | vo-c,cpu | 100 | 0 | 1.60 [1.60, 1.60] | 10 | 33 / 32 / 0.66 [0.06, 0.76] |" in text


def test_vt_against_vo_on_the_same_episodes(tmp_path):
    id_vo = [_rec(0, i, "id", True, 0.5) for i in range(10)]
    id_vt = [_rec(0, i, "id", True, 0.5, "vt-c,cpu,rgb+depth") for i in range(10)]
    vo = [_rec(0, i, "mass_x2.5", i < 5, 0.5) for i in range(10)]
    vt = [_rec(0, i, "mass_x2.5", True, 0.5, "vt-c,cpu,rgb+depth") for i in range(10)]
    result = O.analyse({"vo-c,cpu": (vo, id_vo), "vt-c,cpu,rgb+depth": (vt, id_vt)})
    comp = result["vo_vs_vt"]["vt-c,cpu,rgb+depth vs vo-c,cpu"]
    assert comp["pooled_tsr"]["difference"] == pytest.approx(0.5) and comp["pooled_tsr"]["only_a"] == 5
    assert set(comp["per_condition"]) == {"mass_x2.5"}
    # The command reads each OOD file with its ID file and writes the report, JSON and curves.
    for name, records in (("object_soft_ood_vo-c-cpu", vo), ("object_soft_id_vo-c-cpu", id_vo)):
        (tmp_path / f"{name}.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    O.main([str(tmp_path / "object_soft_ood_vo-c-cpu.jsonl"), "--out", str(tmp_path / "out")])
    assert (tmp_path / "out" / "ood.md").exists() and (tmp_path / "out" / "ood_curves.png").stat().st_size > 0
    with pytest.raises(SystemExit):
        O.main([str(tmp_path / "object_soft_id_vo-c-cpu.jsonl"), "--out", str(tmp_path / "out")])  # not an OOD file
    assert len(O.PAPER_DP_OBJECT_SOFT["vo-c"]) == len(OOD_CONDITIONS)


def test_twins_from_the_ood_machine_replace_the_committed_ones(tmp_path):
    # The committed ID records say every twin succeeded; the twins re-run on the OOD machine say
    # none did: the paired change is read against the re-run, the change of rates against all ID.
    vo = [_rec(0, i, "mass_x2.5", True, 0.5) for i in range(10)]
    (tmp_path / "object_soft_ood_vo-c-cpu.jsonl").write_text("".join(json.dumps(r) + "\n" for r in vo))
    committed = [_rec(0, i, "id", True, 0.5) for i in range(50)]
    (tmp_path / "object_soft_id_vo-c-cpu.jsonl").write_text("".join(json.dumps(r) + "\n" for r in committed))
    (tmp_path / "twins").mkdir()
    rerun = [_rec(0, i, "id", False, 0.5) for i in range(10)]
    (tmp_path / "twins" / "object_soft_id_vo-c-cpu.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rerun))
    result = O.main([str(tmp_path / "object_soft_ood_vo-c-cpu.jsonl"), "--out", str(tmp_path / "out"),
                     "--twins", str(tmp_path / "twins")])
    v = result["variants"]["vo-c,cpu"]
    assert v["paired_tsr"]["difference"] == pytest.approx(1.0) and v["id"]["tsr"] == 1.0
    assert v["stiffness"][1.0]["tsr"] == 0.0  # x1.0 is the twins the OOD episodes pair with
    # The report ends with where each file ran, the twins by their folder.
    where = (tmp_path / "out" / "ood.md").read_text().split("## Where the records ran")[1]
    assert "| object_soft_ood_vo-c-cpu.jsonl | unrecorded |" in where and "| twins/object_soft_id_vo-c-cpu.jsonl |" in where
    with pytest.raises(SystemExit):
        O.main([str(tmp_path / "object_soft_ood_vo-c-cpu.jsonl"), "--out", str(tmp_path / "out"),
                "--twins", str(tmp_path / "nowhere")])


def test_both_soft_suites_in_one_report_each_beside_its_own_paper_entry(tmp_path):
    """A Spatial-Soft run is named with its suite, read against the paper's Spatial-Soft row, and VT is
    compared with VO within a suite only."""
    files = {}
    for suite in ("object_soft", "spatial_soft"):
        for variant in ("vo-c,cpu", "vt-c,cpu"):
            name = variant.split(",")[0]
            files[f"{suite}_id_{name}-cpu"] = [_rec(0, i, "id", True, 0.5, variant, suite) for i in range(10)]
            files[f"{suite}_ood_{name}-cpu"] = [_rec(0, i, "light_67.5", i < 2, 0.5, variant, suite) for i in range(10)]
    for name, records in files.items():
        (tmp_path / f"{name}.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    runs, _ = O.load_runs([tmp_path / f"{n}.jsonl" for n in files if "_ood_" in n])
    assert set(runs) == {"vo-c,cpu", "vt-c,cpu", "vo-c,cpu (spatial_soft)", "vt-c,cpu (spatial_soft)"}
    result = O.analyse(runs)
    assert set(result["vo_vs_vt"]) == {"vt-c,cpu vs vo-c,cpu", "vt-c,cpu (spatial_soft) vs vo-c,cpu (spatial_soft)"}
    text = O.build(result)
    assert "| light_67.5 | 20 / 20 (10) | 20 / 20 (10) | 20 / 20 (10) | 20 / 20 (10) | 0 / 0 | 1 / 1 | 0 / 0 | 19 / 14 |" in text
    assert "11.0 (-4.6) / 8.8 (-4.6)" in text and "25.2 (-7.8) / 17.8 (-7.2)" in text  # the paper's pooled Spatial-Soft rows
    assert all(len(O.PAPER_DP_OOD[s][v]) == len(OOD_CONDITIONS) for s in O.PAPER_DP_OOD for v in O.PAPER_DP_OOD[s])
    # The curves' legend names each line's suite once both are on the plot; one suite alone keeps the bare names.
    assert O.legend_labels(runs) == {"vo-c,cpu": "vo-c,cpu (object_soft)", "vt-c,cpu": "vt-c,cpu (object_soft)",
                                     "vo-c,cpu (spatial_soft)": "vo-c,cpu (spatial_soft)",
                                     "vt-c,cpu (spatial_soft)": "vt-c,cpu (spatial_soft)"}
    object_only = {v: run for v, run in runs.items() if "(" not in v}
    assert O.legend_labels(object_only) == {"vo-c,cpu": "vo-c,cpu", "vt-c,cpu": "vt-c,cpu"}


def test_a_spatial_run_counts_the_other_instance_on_the_plate_by_condition():
    def spatial(task, i, condition, other_on_plate, moved):
        rec = _rec(task, i, condition, not other_on_plate, 0.5, suite="spatial_soft")
        rec.update(instructed_instance="left", other_in_target=other_on_plate,
                   instance_displacement={"left": 0.05, "right": 0.05 if moved else 0.0})
        return rec

    id_records = [spatial(0, i, "id", i < 3, False) for i in range(10)]
    ood = [spatial(0, i, "mass_x2.5", i < 4, i == 9) for i in range(10)]
    text = O.build(O.analyse({"vo-c,cpu (spatial_soft)": (ood, id_records)}))
    assert "| id twins | 3 / 0 (10) |" in text and "| mass_x2.5 | 4 / 1 (10) |" in text
    assert "| light_67.5 | - |" in text and "| pooled | 4 / 1 (10) |" in text
    object_only = O.build(O.analyse({"vo-c,cpu": ([_rec(0, 0, "mass_x2.5", True, 0.5)], [_rec(0, 0, "id", True, 0.5)])}))
    assert "Which instance" not in object_only  # Object records name no instance
