"""Ray execution: the same work items give the same results, and the same episode records, as locally."""

import sys

import pytest

from mani_skill_softvt.parallel import RAY_INSTALL_HINT, init_ray, run_tasks

ray = pytest.importorskip("ray")
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def _square(x, queue):
    """A trivial work item: two messages, then its result."""
    queue.put((x, "start"))
    queue.put((x, "end"))
    return x * x


def _fail(x, queue):
    queue.put(x)
    raise ValueError(f"item {x} failed")


@pytest.fixture(scope="module")
def local_ray():
    """Ray on this machine, shared by the tests of this module; ``run_tasks`` reuses it."""
    # Ray workers cannot import this test module by name: ship its functions by value.
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    ray.init(num_cpus=2, include_dashboard=False)
    yield "local"
    ray.shutdown()
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def _events(ray_address, items, workers=2):
    return list(run_tasks(_square, items, workers, ray_address))


# Both backends start worker processes that import the package (about 45 s of a default run on a
# 2-core EPYC): CI's slow pass; test_parallel keeps a local worker pool in the default run.
@pytest.mark.slow
@pytest.mark.parametrize("backend", ["local", "ray"])
def test_every_item_runs_once_and_its_messages_come_before_its_result(backend, request):
    address = request.getfixturevalue("local_ray") if backend == "ray" else None
    items = [(x,) for x in range(3)]  # more items than the two workers: one waits for a free worker
    events = _events(address, items)
    results = [v for k, v in events if k == "result"]
    assert sorted(results) == [x * x for x in range(3)]
    messages = [v for k, v in events if k == "message"]
    assert sorted(messages) == sorted((x, m) for x in range(3) for m in ("start", "end"))
    at = {v: i for i, (k, v) in enumerate(events)}
    for x in range(3):
        assert at[(x, "start")] < at[(x, "end")] < at[x * x]


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["local", "ray"])
def test_a_failing_item_raises_its_error_after_its_messages(backend, request):
    address = request.getfixturevalue("local_ray") if backend == "ray" else None
    seen = []
    with pytest.raises(ValueError, match="item 7 failed"):
        for kind, value in run_tasks(_fail, [(7,)], 1, address):
            seen.append((kind, value))
    assert seen == [("message", 7)]


def test_no_items_starts_nothing():
    assert list(run_tasks(_square, [], 1, "ray://unreachable:1")) == []


def test_missing_ray_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # makes `import ray` fail
    with pytest.raises(ImportError, match="mani-skill-softvt\\[ray\\]"):
        init_ray("local")
    assert "pip install" in RAY_INSTALL_HINT


@pytest.mark.slow  # a full expert episode on a Ray worker (~40 s)
def test_expert_episode_records_on_ray_are_identical_to_local(local_ray, tmp_path, soft_cube_expert_run):
    from mani_skill_softvt.evaluation.run import RunConfig
    from mani_skill_softvt.evaluation.runner import evaluate
    from mani_skill_softvt.fileio import read_jsonl

    def strip(records):
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in records]

    # The local reference is the session's uninterrupted local run (first episode of it).
    eps, local, _ = soft_cube_expert_run
    eps, local = eps[:1], local[:1]
    ticks = []
    on_ray = evaluate(RunConfig.resolve("expert"), tmp_path / "ray.jsonl", eps, progress=ticks.append, ray_address=local_ray)
    assert local and strip(on_ray) == strip(local)  # same trace, receipt and content hash
    assert local[0]["success"] and sum(ticks) == len(eps)
    # Resume is unchanged: a second Ray run finds every episode done and submits nothing.
    again = evaluate(RunConfig.resolve("expert"), tmp_path / "ray.jsonl", eps, progress=ticks.append, ray_address=local_ray)
    assert again == on_ray and len(read_jsonl(tmp_path / "ray.jsonl")) == len(eps)
