"""Local work items (mani_skill_softvt.parallel): what each worker process starts with."""

import os

from mani_skill_softvt.parallel import WORKER_THREAD_VARS, run_tasks


def _thread_vars(queue):
    return {v: os.environ.get(v) for v in WORKER_THREAD_VARS}


def test_a_worker_runs_one_blas_thread_unless_the_caller_chose(monkeypatch):
    # A worker is one core's job: a BLAS pool per worker would spin against the others.
    for v in WORKER_THREAD_VARS:
        monkeypatch.delenv(v, raising=False)
    monkeypatch.setenv("MKL_NUM_THREADS", "3")  # the caller's choice is kept
    (seen,) = [v for k, v in run_tasks(_thread_vars, [()], 1) if k == "result"]
    assert seen == {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "3"}
    # This process's own environment is as it was.
    assert "OPENBLAS_NUM_THREADS" not in os.environ and os.environ["MKL_NUM_THREADS"] == "3"
