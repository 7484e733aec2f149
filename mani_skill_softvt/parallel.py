"""Run independent work items in a local process pool or as Ray tasks, with one stream of messages.

Evaluation, demo generation and calibration all have the same shape: a few long work items (one
per (suite, task) batch, per task, or per asset; each builds its own env once, which takes
10-20 s, then runs many episodes), each reporting progress or finished records along the way.
:func:`run_tasks` runs ``fn(*args, queue)`` for every ``args`` and yields, in the main process,

- ``("message", item)`` for every item a work item puts on ``queue``, as soon as it is put, and
- ``("result", value)`` when a work item returns, after every message it put.

The backend only changes where the work runs and what the queue is: a spawn-context
``ProcessPoolExecutor`` with a ``multiprocessing.Manager`` queue locally (Warp and SAPIEN do not
survive fork), or Ray remote tasks (one CPU each, no retries) with a ``ray.util.queue.Queue`` actor.
So the work items, their batches and the order of episodes inside a batch are the same on both,
the physics is deterministic per process given the seed, and a record still reaches the main
process (which alone writes the resumable JSONL) the moment its episode ends: progress and
resume behave the same whether the run is local or on a cluster. With Ray, ``workers`` is
ignored: every item is submitted at once and the cluster schedules them on its free CPUs.

Ray is imported only when an address is given. ``"local"`` starts Ray on this machine
(``ray.init()``); anything else is passed to ``ray.init(address=...)`` (``auto``, ``ray://host:10001``).
If Ray is already initialised in this process (e.g. by a caller with its own options), it is reused.
Items that write files (demos, calibration cards) write them on the worker's node, so on a
multi-node cluster their output folder must be on a shared filesystem; evaluation records travel
through the queue and need none.
"""

from __future__ import annotations

import multiprocessing as mp
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor

RAY_INSTALL_HINT = "pip install 'mani-skill-softvt[ray]' (from a checkout: pip install -e '.[ray]')"
POLL_S = 0.2


def run_tasks(fn: Callable, items: Sequence[tuple], workers: int = 1,
              ray_address: str | None = None) -> Iterator[tuple[str, object]]:
    """Run ``fn(*args, queue)`` for each ``args`` in ``items``; yield its messages and results.

    ``fn`` must be a module-level (picklable) function. A work item's exception is re-raised
    here, after the messages it put before failing were yielded.
    """
    if not items:
        return iter(())
    if ray_address is None:
        return _run_local(fn, items, workers)
    return _run_ray(fn, items, ray_address)


def init_ray(address: str):
    """Import Ray and connect to ``address`` ("local" starts it here); return the ``ray`` module."""
    try:
        import ray
    except ImportError as e:
        raise ImportError(f"--ray needs Ray, which is not installed: {RAY_INSTALL_HINT}") from e
    if not ray.is_initialized():
        kwargs = {} if address == "local" else {"address": address}
        ray.init(**kwargs)
    return ray


def _drain(queue, qsize: Callable[[], int] | None = None) -> list:
    """Everything currently on ``queue`` (Manager proxy or Ray queue), oldest first."""
    if qsize is not None:  # Ray queue: one batched call instead of one round trip per item
        n = qsize()
        return queue.get_nowait_batch(n) if n else []
    out = []
    while not queue.empty():
        out.append(queue.get())
    return out


def _run_local(fn: Callable, items: Sequence[tuple], workers: int) -> Iterator[tuple[str, object]]:
    with mp.Manager() as manager:
        queue = manager.Queue()
        with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
            pending = {pool.submit(fn, *args, queue) for args in items}
            try:
                while pending:
                    # Snapshot finished items first: their puts completed before they returned,
                    # so draining afterwards yields all their messages before their results.
                    finished = {f for f in pending if f.done()}
                    for msg in _drain(queue):
                        yield "message", msg
                    for f in finished:
                        yield "result", f.result()  # re-raises the worker's error with its traceback
                    pending -= finished
                    if pending and not finished:
                        time.sleep(POLL_S)
            finally:
                for f in pending:  # on error or Ctrl-C: do not start items that have not begun
                    f.cancel()


def _run_ray(fn: Callable, items: Sequence[tuple], address: str) -> Iterator[tuple[str, object]]:
    ray = init_ray(address)
    from ray.util.queue import Queue

    # num_cpus=0: the queue actor must not take a CPU that a work item could use.
    queue = Queue(actor_options={"num_cpus": 0})
    # max_retries=0: a retried item would put its records twice; fail loudly as locally instead.
    remote = ray.remote(num_cpus=1, max_retries=0)(fn)
    pending = [remote.remote(*args, queue) for args in items]
    try:
        while pending:
            finished, pending = ray.wait(pending, num_returns=len(pending), timeout=POLL_S)
            for msg in _drain(queue, queue.qsize):
                yield "message", msg
            for ref in finished:
                yield "result", ray.get(ref)  # re-raises the task's error (a RayTaskError)
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        queue.shutdown()
