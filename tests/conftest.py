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
