"""Provenance (mani_skill_softvt/provenance.py): one place for the version markers, the seal of a
record and the table of what an older file lacks; each row of the table names the code that acts
on it, and that code exists."""

import importlib

import pytest

from mani_skill_softvt import actions, provenance
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
