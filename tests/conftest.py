"""Fixtures shared across test modules: expensive closed-loop runs are done once per session."""

import pytest


@pytest.fixture(scope="session")
def soft_cube_expert_run(tmp_path_factory):
    """One ID episode of the scripted expert on Object-Soft task 3 (the soft cube), run locally.

    Used by the runner's resume test and by the Ray test as the uninterrupted local reference.
    Returns (episodes, records, path of the JSONL the records were written to).
    """
    from mani_skill_softvt.evaluation.protocols import episodes
    from mani_skill_softvt.evaluation.run import RunConfig
    from mani_skill_softvt.evaluation.runner import evaluate

    eps = episodes("object_soft", "id", tasks=[3], per_task=1)
    path = tmp_path_factory.mktemp("expert_run") / "full.jsonl"
    return eps, evaluate(RunConfig.resolve("expert"), path, eps), path


# README's test command runs two pytest-xdist workers (--dist loadgroup). Each module stays on one
# worker, so its module-scoped envs are built once; the modules that share the session's expert run
# (above) go together, so it is run once.
SHARES_EXPERT_RUN = {"test_evaluation_runner", "test_planner", "test_ray"}


def pytest_collection_modifyitems(config, items):
    if not config.pluginmanager.hasplugin("xdist"):
        return
    for item in items:
        module = item.module.__name__.rpartition(".")[2]
        item.add_marker(pytest.mark.xdist_group("expert_run" if module in SHARES_EXPERT_RUN else module))
