"""Fixtures shared across test modules: expensive closed-loop runs are done once per session."""

import pytest

# Before any test module loads NumPy or torch: the package's import pins their CPU dispatch
# (mani_skill_softvt/provenance/numerics.py), so the tests run under the numerics every record names.
import mani_skill_softvt  # noqa: F401


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


# README's test command runs two pytest-xdist workers. Each module stays on one worker, so its
# module-scoped envs are built once, and the modules that share the session's expert run (above) go
# together, so it runs once. A scheduler, not xdist_group marks: xdist 3.8 reads those before a
# conftest's collection hook runs, and under pytest 9 it cannot rename the node ids it groups by
# (pytest-xdist issue 1386).
SHARES_EXPERT_RUN = {"test_evaluation_runner", "test_planner", "test_ray"}


@pytest.hookimpl(optionalhook=True)  # the hook exists only where xdist is installed
def pytest_xdist_make_scheduler(config, log):
    from xdist.scheduler import LoadScopeScheduling

    class ModuleScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            module = nodeid.split("::", 1)[0].rpartition("/")[2].removesuffix(".py")
            return "expert_run" if module in SHARES_EXPERT_RUN else module

    return ModuleScheduling(config, log)
