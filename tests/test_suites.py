"""Suite and task definitions: verbatim instructions of the paper's task table."""

import pytest

from mani_skill_softvt.tasks.suites import NUM_TASKS, SUITES, list_tasks, task_spec


def test_four_suites_of_ten_tasks():
    assert set(SUITES) == {"object_soft", "spatial_soft", "object_rigid", "spatial_rigid"}
    for suite in SUITES:
        assert len(list_tasks(suite)) == NUM_TASKS == 10


def test_instructions_are_verbatim():
    assert task_spec("object_soft", 0).instruction == "Pick up the white swirled pastry and place it in the basket."
    assert task_spec("object_soft", 7).instruction == "Pick up the golden knotted pastry and place it in the basket."
    assert task_spec("spatial_soft", 1).instruction == "Pick up the right panda-face pastry and place it on the plate."
    assert task_spec("spatial_soft", 6).instruction == "Pick up the right golden pastry and place it on the plate."
    assert task_spec("spatial_soft", 7).instruction == (
        "Pick up the left soft cream-colored rectangular block and place it on the plate.")
    sides = [t.side for t in list_tasks("spatial_soft")]
    assert [i for i, s in enumerate(sides) if s == "right"] == [1, 6]


def test_rigid_suites_mirror_soft_suites_with_twins():
    for layout in ("object", "spatial"):
        for soft, rigid in zip(list_tasks(f"{layout}_soft"), list_tasks(f"{layout}_rigid")):
            assert rigid.instruction == soft.instruction
            assert rigid.soft_asset_id == soft.asset_id
            assert rigid.asset_id == soft.asset_id.replace("soft_", "rigid_", 1)


def test_bad_task_requests_say_what_is_allowed():
    with pytest.raises(ValueError, match=r"\[0, 9\]"):
        task_spec("object_soft", 10)
    with pytest.raises(ValueError, match="object_rigid"):
        task_spec("object_hard", 0)
