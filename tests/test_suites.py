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


def test_suite_objects_say_layout_target_and_rigidity():
    from mani_skill_softvt.tasks.suites import get_suite

    for name, suite in SUITES.items():
        assert suite.name == name and suite.rigid == name.endswith("_rigid")
        assert suite.target == ("basket" if suite.layout == "object" else "plate")
        assert all(t.rigid == suite.rigid and t.target == suite.target for t in list_tasks(name))
    with pytest.raises(ValueError, match="object_soft"):
        get_suite("object_squishy")
    with pytest.raises(ValueError, match="integer"):
        task_spec("object_soft", True)  # a bool is not a task id


def test_reset_factors_resolve_once_from_a_condition_or_single_factors():
    from mani_skill_softvt.tasks.suites import OOD_CONDITIONS, PhysicalFactors, resolve_factors

    assert resolve_factors(None) == resolve_factors({"ood": "id"}) == PhysicalFactors()
    for name, (key, value) in OOD_CONDITIONS.items():
        f = resolve_factors({"ood": name})
        assert getattr(f, key) == value
        assert all(getattr(f, k) == getattr(PhysicalFactors(), k) for k in ("light_intensity", "mass_scale",
                                                                             "youngs_modulus_scale") if k != key)
    assert resolve_factors({"mass_scale": 2, "light_intensity": 90}) == PhysicalFactors(90.0, 2.0, 1.0)
    with pytest.raises(ValueError, match="also mass_scale"):
        resolve_factors({"ood": "mass_x2.5", "mass_scale": 1.5})
