"""Provenance (mani_skill_softvt/provenance/): one place for the version markers, the seal of a
record and the table of what an older file lacks; each row of the table names the code that acts
on it, and that code exists."""

import importlib
from pathlib import Path

import pytest

from mani_skill_softvt import provenance
from mani_skill_softvt.contracts import actions
from mani_skill_softvt.fileio import file_sha256
from mani_skill_softvt.data import trajectory
from mani_skill_softvt.evaluation import records
from mani_skill_softvt.physics.config import DEFAULT_PHYSICS
from mani_skill_softvt.tactile import constants as tactile_constants


@pytest.mark.parametrize("row", provenance.UPGRADES, ids=lambda u: f"{u.file}: {u.lacks}")
def test_each_row_of_the_upgrade_table_names_the_code_that_reads_such_a_file(row):
    module, _, name = row.where.partition(":")
    assert hasattr(importlib.import_module(module), name), row.where
    assert row.read_as and row.remedy


def test_the_markers_the_code_writes_are_provenances():
    assert actions.GRIPPER_ACTION_VERSION is provenance.GRIPPER_ACTION_VERSION
    assert trajectory.RENDER_VERSION is provenance.RENDER_VERSION
    assert tactile_constants.model_version(True) == provenance.TACTILE_SOFT_MODEL_VERSION
    assert tactile_constants.model_version(False) == provenance.TACTILE_MODEL_VERSION
    assert DEFAULT_PHYSICS.signature()["EE_ORIENTATION_AXIS_ANGLE"] == provenance.EE_ORIENTATION_AXIS_ANGLE
    assert records.record_hash is provenance.record_hash


def test_the_seal_covers_everything_but_the_wall_time():
    record = provenance.seal({"r_max": 0.5, "wall_s": 1.0, "success": True})
    assert record["record_sha256"] == provenance.record_hash({**record, "wall_s": 9.0})
    assert record["record_sha256"] != provenance.record_hash({**record, "r_max": 0.6})


def test_a_signature_difference_names_the_setting_and_a_missing_signature_says_so():
    now = DEFAULT_PHYSICS.signature()
    assert provenance.signature_differences(dict(now), now) == []
    assert provenance.signature_differences({**now, "VBD_ITERATIONS": 3.0}, now) == \
        ["VBD_ITERATIONS: recorded 3.0, now 5.0"]
    older = {k: v for k, v in now.items() if k != "EE_ORIENTATION_AXIS_ANGLE"}  # made before the hand fix
    assert provenance.signature_differences(older, now) == ["EE_ORIENTATION_AXIS_ANGLE: recorded None, now 1.0"]
    assert "made before signatures existed" in provenance.signature_differences(None, now)[0]


def test_a_data_folders_old_spelling_reads_as_its_new_name(tmp_path, monkeypatch, capsys):
    """The committed data folders were renamed (``*-data``): a path in the old spelling maps to the new
    one, and a command given such a path reads the file there with a note; a path that exists as given,
    or under no renamed folder, is left as it is."""
    from mani_skill_softvt.cli.arguments import existing_path
    from mani_skill_softvt.provenance import RENAMED_DATA_FOLDERS, current_data_path

    assert current_data_path("baselines/results/object_soft_id_vo-c-cpu.jsonl") == \
        "campaign-data/results/object_soft_id_vo-c-cpu.jsonl"
    assert current_data_path("./demos/spatial_soft/stats.json") == "demo-data/spatial_soft/stats.json"
    assert current_data_path("baselines/policies/vo-c-cpu.pt") == "campaign-data/policies/vo-c-cpu.pt"
    assert current_data_path("outputs/eval/x.jsonl") is None
    assert all(new.endswith("-data/") or new.startswith("campaign-data/") for new in RENAMED_DATA_FOLDERS.values())
    monkeypatch.chdir(tmp_path)
    (tmp_path / "campaign-data" / "results").mkdir(parents=True)
    (tmp_path / "campaign-data" / "results" / "r.jsonl").write_text("")
    found = existing_path(Path("baselines/results/r.jsonl"), "--reproduce")
    assert found == Path("campaign-data/results/r.jsonl")
    assert "--reproduce baselines/results/r.jsonl: that folder was renamed; reading campaign-data/results/r.jsonl" \
        in capsys.readouterr().err
    (tmp_path / "baselines" / "results").mkdir(parents=True)
    (tmp_path / "baselines" / "results" / "r.jsonl").write_text("")  # a user's own file there is theirs
    assert existing_path(Path("baselines/results/r.jsonl"), "--reproduce") == Path("baselines/results/r.jsonl")
    assert existing_path(Path("nowhere.jsonl"), "--a") == Path("nowhere.jsonl")  # the command's own error follows


def test_a_policy_named_by_its_folders_old_spelling_is_one_file_with_its_new_one(tmp_path, monkeypatch, capsys):
    """The sealed records name their policy by ``baselines/policies/...``: a run resumed or reproduced
    from the moved file is the same run, its records compare equal on the path, and a spec in the old
    spelling loads the file where it lies now, with a note."""
    import shutil

    from mani_skill_softvt.evaluation.policies import resolve_policy
    from mani_skill_softvt.evaluation.runner import is_run_record, record_differences, single_run
    from mani_skill_softvt.provenance import same_data_path

    old, new = "baselines/policies/vo-c-cpu.pt", "campaign-data/policies/vo-c-cpu.pt"
    assert same_data_path(old, new) and same_data_path("./" + old, new) and same_data_path(None, None)
    assert not same_data_path(old, "campaign-data/policies/vt-c-cpu.pt") and not same_data_path(old, None)
    assert same_data_path("./campaign-data/results/x.jsonl", "campaign-data/results/x.jsonl")
    assert same_data_path("runs/../baselines/policies/vo-c-cpu.pt", new)
    assert not same_data_path("ws://gpu-box:8000", "ws:/gpu-box:8000") and not same_data_path("", ".")
    rec = {"policy": old, "obs_mode": "rgb", "policy_sha256": "ab", "suite": "object_soft", "task_id": 0,
           "condition": "id", "seed": 1, "success": True}
    assert is_run_record(rec, {"policy": new, "obs_mode": "rgb"}, "ab")
    assert not is_run_record(rec, {"policy": new, "obs_mode": "rgb"}, "cd")  # another file's content
    assert record_differences(rec, {**rec, "policy": new}) == []
    assert record_differences(rec, {**rec, "policy": "campaign-data/policies/vt-c-cpu.pt"}) == ["policy"]
    assert single_run([rec, {**rec, "policy": new, "seed": 2}], tmp_path / "r.jsonl") == "ab"

    committed = Path(__file__).resolve().parents[1] / new
    monkeypatch.chdir(tmp_path)
    (tmp_path / "campaign-data" / "policies").mkdir(parents=True)
    shutil.copy(committed, tmp_path / new)
    source = resolve_policy(old)
    assert source.spec == new and source.sha256 == file_sha256(committed)
    assert f"policy {old}: that folder was renamed; reading {new}" in capsys.readouterr().err


def test_the_checkout_keeps_its_data_in_folders_no_package_can_be_named(tmp_path):
    """Each kind of data resolves to its renamed folder, and git tracks nothing under an old spelling (a
    checkout pulled across the rename may keep ignored files there: docs/install.md says where they go)."""
    import shutil
    import subprocess

    from mani_skill_softvt.paths import CHECKOUT_DATA_FOLDERS, REPO_DIR, data_dir

    for kind, folder in CHECKOUT_DATA_FOLDERS.items():
        assert (REPO_DIR / folder).is_dir() and not folder.isidentifier()
        assert data_dir("SOFTVT_NO_SUCH_VARIABLE", kind) == REPO_DIR / folder
    assert (REPO_DIR / "campaign-data" / "results").is_dir()
    if shutil.which("git") is None or not (REPO_DIR / ".git").exists():
        pytest.skip("not a git checkout")
    old = [o.rstrip("/") for o in provenance.RENAMED_DATA_FOLDERS]
    tracked = subprocess.run(["git", "ls-files", "--", *old], cwd=REPO_DIR, capture_output=True, text=True,
                             check=True).stdout.split()
    assert tracked == [], f"files committed under a data folder's old name: {tracked[:5]}"
