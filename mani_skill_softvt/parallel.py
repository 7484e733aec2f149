"""Run independent work items in local processes or as Ray tasks, with one stream of messages.

Evaluation, demo generation and calibration all have the same shape: a few long work items (one
per (suite, task) batch, per task, or per asset; each builds its own env once, which takes
10-20 s, then runs many episodes), each reporting progress or finished records along the way.
:func:`run_tasks` runs ``fn(*args, queue)`` for every ``args`` and yields, in the main process,

- ``("message", item)`` for every item a work item puts on ``queue``, as soon as it is put, and
- ``("result", value)`` when a work item returns, after every message it put, and
- with ``report_deaths``, ``("died", (index, reason))`` when a work item's process dies.

The backend only changes where the work runs and what the queue is: locally one spawn-context
process per work item, at most ``workers`` at a time (Warp and SAPIEN do not survive fork), all
putting on one ``multiprocessing`` queue and each killed by the kernel if the main process dies;
or Ray remote tasks (one CPU each, no retries) with a ``ray.util.queue.Queue`` actor.
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

import ctypes
import multiprocessing as mp
import os
import pickle
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from queue import Empty

from .provenance.numerics import chosen, environment

RAY_INSTALL_HINT = "pip install 'mani-skill-softvt[ray]' (from a checkout: pip install -e '.[ray]')"
# A work item is one core's job. A BLAS thread pool in each would spin against the other workers:
# beside one other job, a reset's 1,296 small matrix inverses (Newton's tet builder) took 6-15 s
# instead of 1.7 s, while a step, whose matrices are as small, gained nothing from the threads.
# With one BLAS thread, 10 committed VO-C evaluation episodes were reproduced bit for bit. A
# variable the caller has set is kept. Ray sets OMP_NUM_THREADS to a task's CPUs (one here)
# unless it is set, and OpenBLAS falls back to it.
WORKER_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
_ENV_LOCK = threading.Lock()  # os.environ is the process's: two run_tasks in threads must not interleave
POLL_S = 0.2
_MESSAGE, _RESULT, _ERROR = "message", "result", "error"


def run_tasks(fn: Callable, items: Sequence[tuple], workers: int = 1, ray_address: str | None = None,
              report_deaths: bool = False, numerics: str | None = None) -> Iterator[tuple[str, object]]:
    """Run ``fn(*args, queue)`` for each ``args`` in ``items``; yield its messages and results.

    ``fn`` must be a module-level (picklable) function. A work item's exception is re-raised
    here, after the messages it put before failing were yielded. A work item whose process dies
    (SIGKILL, out of memory, a segfault in native code) raises :class:`WorkerDiedError`, or with
    ``report_deaths`` yields ``("died", (index_in_items, reason))`` while the other items go on.
    ``numerics`` (:mod:`mani_skill_softvt.provenance.numerics`): the numerics the work items run under; None,
    this process's (the pins, unless ``SOFTVT_NUMERICS`` chose otherwise).
    """
    if not items:
        return iter(())
    if ray_address is None:
        return _run_local(fn, items, workers, report_deaths, numerics or chosen().name)
    return _run_ray(fn, items, ray_address, report_deaths, numerics or chosen().name)


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


class WorkerDiedError(RuntimeError):
    """A work item's process died (killed, out of memory, a crash in native code) before returning."""

    def __init__(self, index: int, reason: str):
        super().__init__(f"work item {index}: {reason}")
        self.index, self.reason = index, reason


class WorkerTraceback(Exception):
    """The traceback of a work item's error, as text from the worker process."""

    def __str__(self):
        return "\n" + self.args[0]


def _exit_with_parent(parent_pid: int) -> None:
    """Have the kernel kill this process when its parent dies (Linux; elsewhere a no-op).

    Without it, a ``kill -9`` of the evaluator leaves its workers (each ~850 MB with the simulator
    loaded) running forever, since nothing else ever tells them to stop.
    """
    if sys.platform.startswith("linux"):
        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent_pid:  # the parent died before the line above took effect
        os._exit(1)


def _child(fn: Callable, index: int, args: tuple, queue, parent_pid: int) -> None:
    """Body of one local work item's process: its messages, then ("result"|"error", index, ...)."""
    _exit_with_parent(parent_pid)
    tagged = _TaggedQueue(queue, index)
    try:
        value = fn(*args, tagged)
    except BaseException as e:  # noqa: BLE001 - every failure goes back to the parent
        tb = traceback.format_exc()
        try:
            pickle.dumps(e)
        except Exception:  # an exception that cannot travel: send its text
            e = RuntimeError(f"{type(e).__name__}: {e}")
        queue.put((_ERROR, index, (e, tb)))
        return
    queue.put((_RESULT, index, value))


class _TaggedQueue:
    """What a local work item sees as ``queue``: ``put`` tags each message with the item's index."""

    def __init__(self, queue, index: int):
        self._queue, self._index = queue, index

    def put(self, item) -> None:
        self._queue.put((_MESSAGE, self._index, item))


def _run_local(fn: Callable, items: Sequence[tuple], workers: int,
               report_deaths: bool, numerics: str) -> Iterator[tuple[str, object]]:
    # One process per work item rather than a ProcessPoolExecutor: a pool that loses a process is
    # broken for every item still queued, and its Manager process outlives a killed parent. Here a
    # dead process costs only its own item, and every child dies with the parent (see _exit_with_parent).
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    waiting = list(enumerate(items))[::-1]
    running: dict[int, mp.process.BaseProcess] = {}
    try:
        while waiting or running:
            while waiting and len(running) < workers:
                index, args = waiting.pop()
                p = ctx.Process(target=_child, args=(fn, index, args, queue, os.getpid()))
                with _worker_environment(numerics):
                    p.start()
                running[index] = p
            try:
                kind, index, payload = queue.get(timeout=POLL_S)
            except Empty:
                # A process that exited without sending its result or error died. Whatever it put
                # is in the pipe before it exits (the queue's feeder thread is joined at exit), so
                # the processes seen dead *before* the queue reads empty once more are dead for sure.
                dead = [i for i, p in running.items() if not p.is_alive()]
                if not dead:
                    continue
                try:
                    kind, index, payload = queue.get_nowait()
                except Empty:
                    for index in dead:
                        p = running.pop(index)
                        p.join()
                        reason = f"its process died (exit code {p.exitcode}{_signal_name(p.exitcode)})"
                        if not report_deaths:
                            raise WorkerDiedError(index, reason) from None
                        yield "died", (index, reason)
                    continue
            if kind == _MESSAGE:
                yield "message", payload
                continue
            running.pop(index).join()
            if kind == _ERROR:
                exc, tb = payload
                raise exc from WorkerTraceback(tb)
            yield "result", payload
    finally:
        for p in running.values():  # on error or Ctrl-C: stop what is still running
            p.kill()
            p.join()
        queue.close()


@contextmanager
def _worker_environment(numerics: str):
    """The environment a spawned worker starts with (it reads it as it imports numpy and torch): one
    BLAS and OpenMP thread unless the caller chose otherwise, and the variables of ``numerics``
    (:func:`mani_skill_softvt.provenance.numerics.environment`); this process's own is restored after."""
    with _ENV_LOCK:
        wanted = {**{v: "1" for v in WORKER_THREAD_VARS if v not in os.environ}, **environment(numerics)}
        saved = {v: os.environ.get(v) for v in wanted}
        try:
            _set_environ(wanted)
            yield
        finally:
            _set_environ(saved)


def _set_environ(values: dict[str, str | None]) -> None:
    for var, value in values.items():
        if value is None:
            os.environ.pop(var, None)
        else:
            os.environ[var] = value


def _signal_name(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        try:
            return f", {signal.Signals(-exitcode).name}"
        except ValueError:
            pass
    return ""


def _run_ray(fn: Callable, items: Sequence[tuple], address: str, report_deaths: bool,
             numerics: str) -> Iterator[tuple[str, object]]:
    env_vars = environment(numerics)
    if any(v is None for v in env_vars.values()):
        # A Ray worker inherits the raylet's variables, and runtime_env can set but not unset one.
        raise ValueError(f"numerics {numerics!r} unpin some of the CPU dispatch, which Ray workers cannot do: "
                         "run it locally (without --ray)")
    ray = init_ray(address)
    from ray.exceptions import WorkerCrashedError
    from ray.util.queue import Queue

    # num_cpus=0: the queue actor must not take a CPU that a work item could use.
    queue = Queue(actor_options={"num_cpus": 0})
    # max_retries=0: a retried item would put its records twice; fail loudly as locally instead.
    # The pins reach a Ray worker through its runtime_env, set before it imports anything.
    remote = ray.remote(num_cpus=1, max_retries=0, runtime_env={"env_vars": env_vars})(fn)
    index_of = {remote.remote(*args, queue): i for i, args in enumerate(items)}
    pending = list(index_of)
    try:
        while pending:
            finished, pending = ray.wait(pending, num_returns=len(pending), timeout=POLL_S)
            n = queue.qsize()  # one batched call instead of one round trip per message
            for msg in queue.get_nowait_batch(n) if n else []:
                yield "message", msg
            for ref in finished:
                try:
                    value = ray.get(ref)  # re-raises the task's error (a RayTaskError)
                except WorkerCrashedError as e:
                    if not report_deaths:
                        raise WorkerDiedError(index_of[ref], str(e)) from e
                    yield "died", (index_of[ref], f"its Ray worker died: {e}")
                    continue
                yield "result", value
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        queue.shutdown()
