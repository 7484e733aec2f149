"""Stored demos rendered into observations (cameras, touch) on their own timeline, at the size a
policy takes, resumable per task and per ten episodes. The command is
``python -m mani_skill_softvt.demos render`` (:mod:`mani_skill_softvt.cli.demos`)."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
from tqdm import tqdm

from ..data.demo_set import DemoSet
from ..data.trajectory import (
    episode_digest,
    holds_twin_contact,
    open_h5,
    rendering_current,
    rendering_parts_dir,
    state_dict_at,
    write_rendering,
)
from ..evaluation.wrapper import make_env
from ..contracts.observations import camera_sensor_configs, camera_size_name, flatten_batch, is_native_camera_size, tactile_keys
from ..parallel import run_tasks
from ..tasks.objects import TWIN_CONTACT_STATE
from ..tasks.suites import get_suite


# Observation keys a rendering must have to count as current (older renderings lack the depth map).
CURRENT_RENDER_KEYS = {"rgb+tactile": tuple(tactile_keys(("depth",)))}


def render_observations(trajectory_h5: Path, out_h5: Path, suite: str, task_id: int, obs_mode: str,
                        camera_size: tuple[int, int] | None = None, progress=None) -> tuple[int, int]:
    """Re-render stored episodes into ``obs_mode`` observations on the same 20 Hz timeline, the
    cameras at ``camera_size`` = (height, width) (None: 224x224). Rendering at the size a policy
    takes spends no raster time on pixels it would shrink away.

    Every recorded env state (reset + one per step) is restored and observed in order, so the
    cameras, the tactile images (whose shear tracking follows the episode) and the actions share
    one timeline with no resampling; the file is written by
    :func:`~mani_skill_softvt.data.trajectory.write_rendering`, which keeps the episodes an earlier
    ``out_h5`` already holds and, rendering ten episodes to a part file, those of a run killed
    mid-task. The states are restored, not re-simulated (ManiSkill's
    ``replay_trajectory --use-env-states`` steps the physics before each restore). Returns the
    episodes in the file and how many were rendered now; ``progress(1)`` per episode.
    """
    env = None
    spec = get_suite(suite)
    touch_of_twins = spec.rigid and spec.frames_tactile_model(obs_mode) is not None

    def observe(seed: int, states: dict) -> list[dict]:
        nonlocal env
        if touch_of_twins and TWIN_CONTACT_STATE not in states:
            # PhysX has no contacts for a restored state: the pinched twin would show a blank gel.
            raise ValueError(f"{trajectory_h5}: seed {seed} was recorded before the rigid twins' contact wrenches "
                             f"were part of the env state, so its touch cannot be rendered; record the demos again "
                             f"(move the episode files aside: 'python -m mani_skill_softvt.demos generate --suite "
                             f"{suite}' records the seeds its QC logs list)")
        if env is None:
            env = make_env(suite, task_id, dsr=False, obs_mode=obs_mode, camera_size=camera_size)
        env.reset(seed=seed)
        frames = []
        for t in range(len(next(iter(states.values())))):
            env.unwrapped.set_state_dict(state_dict_at(states, t))
            frames.append(flatten_batch(env.unwrapped.get_obs()))
        return frames

    try:
        return write_rendering(trajectory_h5, out_h5, obs_mode, observe, camera_sensor_configs(camera_size),
                               CURRENT_RENDER_KEYS.get(obs_mode, ()), progress,
                               tactile_model=get_suite(suite).frames_tactile_model(obs_mode))
    finally:
        if env is not None:
            env.close()


def _render_task(suite: str, task_id: int, out: str, obs_mode: str, camera_size, queue) -> tuple[int, int, int]:
    """One task's rendering (a work item of :func:`~mani_skill_softvt.parallel.run_tasks`): the
    task, its episodes, how many were rendered now (the rest were current); one message per episode."""
    demo_set = DemoSet(Path(out), suite)
    src, dst = demo_set.trajectory(task_id), demo_set.rendered(task_id, obs_mode, camera_size)
    with demo_set.task_lock(task_id):
        if _task_rendered(demo_set, task_id, obs_mode, camera_size):  # by another run meanwhile
            episodes = _episodes(src)
            for _ in range(episodes):
                queue.put(1)
            return task_id, episodes, 0
        return task_id, *render_observations(src, dst, suite, task_id, obs_mode, camera_size, progress=queue.put)


def _task_rendered(demo_set: DemoSet, task_id: int, obs_mode: str, camera_size) -> bool:
    """Whether the task's rendering in ``obs_mode`` at ``camera_size`` is current (:func:`rendering_is_current`);
    a twin's touch rendered from states without its contact wrenches (a blank gel) never is."""
    suite = get_suite(demo_set.suite)
    if suite.rigid and suite.frames_tactile_model(obs_mode) is not None and demo_set.trajectory(task_id).exists():
        with open_h5(demo_set.trajectory(task_id)) as f:
            if not all(holds_twin_contact(f[k]) for k in f.keys()):
                return False
    return rendering_is_current(demo_set.trajectory(task_id), demo_set.rendered(task_id, obs_mode, camera_size),
                                CURRENT_RENDER_KEYS.get(obs_mode, ()), suite.frames_tactile_model(obs_mode))


def _episodes(trajectory_h5: Path) -> int:
    with open_h5(trajectory_h5) as f:
        return len(f.keys())


def rendering_is_current(trajectory_h5: Path, rendered_h5: Path, needed: tuple[str, ...] = (),
                         tactile_model: int | None = None) -> bool:
    """Whether ``rendered_h5`` holds exactly the episodes of ``trajectory_h5``, each rendered from
    the same states (:func:`~mani_skill_softvt.data.trajectory.rendering_current`: the source's
    digest, the ``needed`` observation keys, frames of ``tactile_model`` if given); a re-run of
    render skips such a task."""
    if not rendered_h5.exists():
        return False
    try:
        with h5py.File(trajectory_h5, "r") as a, h5py.File(rendered_h5, "r") as b:
            return set(a.keys()) == set(b.keys()) and all(
                rendering_current(b[k], episode_digest(a[k]), needed, tactile_model) for k in a.keys())
    except OSError:  # unreadable: render it again
        return False


def render(suite: str, tasks: list[int], out: Path, obs_mode: str, camera_size: tuple[int, int] | None = None,
           workers: int = 1) -> list[tuple[int, int, int]]:
    """Render the stored demos of ``tasks`` into ``obs_mode`` observations, the cameras at
    ``camera_size`` (None: 224x224), ``workers`` tasks at a time, skipping tasks whose rendering is
    current; prints a line per task and shows progress. Returns (task, episodes, rendered now) per
    task rendered; CorruptDataError names a damaged file."""
    demo_set = DemoSet(out, suite)
    todo = []
    for t in tasks:
        src, dst = demo_set.trajectory(t), demo_set.rendered(t, obs_mode, camera_size)
        if not src.exists():
            print(f"task {t}: no demos at {src}; run generate first")
        elif _task_rendered(demo_set, t, obs_mode, camera_size):
            print(f"task {t}: already rendered (delete {dst.name} to redo it)")
            shutil.rmtree(rendering_parts_dir(dst), ignore_errors=True)  # a run killed after its last pack
        else:
            todo.append((suite, t, str(out), obs_mode, camera_size))
    size = "" if is_native_camera_size(camera_size) else f" {camera_size_name(camera_size)}"
    done = []
    episodes = sum(_episodes(demo_set.trajectory(item[1])) for item in todo)
    with tqdm(total=episodes, desc=f"render {obs_mode}{size}", unit="episode") as bar:
        for kind, value in run_tasks(_render_task, todo, workers):
            if kind == "message":
                bar.update(value)
            elif kind == "result":
                done.append(value)
                bar.write(f"task {value[0]}: {value[1]} episodes, {value[2]} rendered now, "
                          f"{value[1] - value[2]} kept from the previous rendering")
    return done
