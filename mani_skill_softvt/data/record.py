"""ManiSkill's ``RecordEpisode`` with SoftVT's evaluator stream and episode metadata beside it.

:class:`SoftVTRecordEpisode` records exactly what ``RecordEpisode`` records (``traj_<i>/obs``,
``actions``, ``env_states`` with the FEM state, ``success``, ``fail``, ... and the ``.json`` with
``env_info`` and one entry per episode), and adds per episode:

- ``traj_<i>/evaluator/``: what scores the episode and never enters an observation: the
  instructed object's FEM nodes (T+1, N, 3), every object's centroid (T+1, K, 3), D_t, R_t and
  the scene's collapsed tets (T+1), grasp, drop and pad-force events (T), and tau_o (all float32/float64/bool arrays);
- ``traj_<i>/actions_binary`` (continuous-gripper modes): the actions with the gripper as the
  ``<mode>_binary`` command (closure > 0 is "close": 1 in ``pd_ee_pose``, -1 in ManiSkill's modes);
- in the episode's json entry and as the group's attributes: ``instruction``, ``target_instance``
  and whatever the episode's producer put in :attr:`SoftVTRecordEpisode.episode_metadata` (the
  expert: ``closure``, ``planner``); the json also gets ``r_max``, the group ``seed``.

``env_info.env_id`` is written as the task's own id, module-qualified
(``mani_skill_softvt:SoftVTObjectSoft-Task3-v1``, :func:`~mani_skill_softvt.tasks.suites.recorded_env_id`):
gymnasium imports the module named before the colon, so ManiSkill's own tools (``python -m
mani_skill.trajectory.replay_trajectory``, its worker processes, its baselines' ``--env-id``) make
the same task from the id alone, without importing this package first. ``env_kwargs`` keeps
``task_id`` and records ``gripper_action_version`` (:mod:`mani_skill_softvt.tasks.robot`).

Wrap a DSR-wrapped env (:func:`mani_skill_softvt.evaluation.wrapper.make_env`) to get R_t; a bare
env records D_t only.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from pathlib import Path

import h5py
import numpy as np
from mani_skill.utils.io_utils import dump_json
from mani_skill.utils.logging_utils import logger
from mani_skill.utils.wrappers.record import RecordEpisode

from ..rollout import EvaluatorTrace
from ..contracts.actions import action_closure, gripper_action, normalized_gripper
from ..tasks.suites import recorded_env_id

# The evaluator trace's fields a recorded episode keeps beside "nodes" (float32), in this order.
RECORDED = ("object_centroids", "deformation", "deformation_ratio", "collapsed_tets", "is_grasped", "dropped",
            "pad_force")


class SoftVTRecordEpisode(RecordEpisode):
    """``RecordEpisode`` plus the evaluator stream and episode metadata (module docstring)."""

    def __init__(self, env, output_dir, *args, **kwargs):
        super().__init__(env, output_dir, *args, **kwargs)
        self.episode_metadata: dict = {}
        self._trace: EvaluatorTrace | None = None
        info = getattr(self, "_json_data", {}).get("env_info")
        if info is not None:
            task = self.env.unwrapped.task
            info["env_id"] = recorded_env_id(task.suite, task.task_id)

    # ------------------------------------------------------------------ stream
    def reset(self, *args, **kwargs):
        obs, info = super().reset(*args, **kwargs)
        self.episode_metadata = {}
        self._trace = EvaluatorTrace()  # the instructed object
        self._trace.on_reset(self, obs, info)
        return obs, info

    def step(self, action):
        obs, rew, terminated, truncated, info = super().step(action)
        self._trace.on_step(self, action, obs, info)
        return obs, rew, terminated, truncated, info

    # ------------------------------------------------------------------ files
    def flush_trajectory(self, verbose=False, ignore_empty_transition=True, env_idxs_to_flush=None, save=True):
        before = self._episode_id
        super().flush_trajectory(verbose, ignore_empty_transition, env_idxs_to_flush, save)
        if save and self.save_trajectory and self._episode_id != before and self._trace is not None:
            self._write_evaluator(self._h5_file[f"traj_{self._episode_id}"], self._json_data["episodes"][-1])
            dump_json(self._json_path, self._json_data, indent=2)

    def _write_evaluator(self, group, episode: dict) -> None:
        u = self.env.unwrapped
        if "env_states" in group:
            _gzip_large_datasets(group["env_states"])
        t = self._trace.arrays()
        ev = {"nodes": t["nodes"].astype(np.float32), **{k: t[k] for k in RECORDED if k in t}}
        tau_o = getattr(self.env, "tau_o", None)
        g = group.create_group("evaluator")
        for k, v in ev.items():
            # FEM nodes compress well; gzip is lossless and deterministic.
            g.create_dataset(k, data=v, **(GZIP if v.size > 4096 else {}))
        if tau_o is not None:
            g.create_dataset("tau_o", data=np.float64(tau_o))
        if not u.control_mode.endswith("_binary"):
            # The same actions in the binary gripper encoding (any commanded closure is "close"),
            # what the paper's binary-gripper variants train on.
            actions = group["actions"][()]
            binary = actions.copy()
            binary[:, -1] = binary_gripper_column(actions[:, -1], u.control_mode)
            group.create_dataset("actions_binary", data=binary)
        meta = dict(seed=int(episode["episode_seed"]), instruction=u.instruction, target_instance=u.target_instance,
                    **self.episode_metadata)
        group.attrs.update(meta)  # also on the group: a reader of one h5 needs no json
        meta.pop("seed")
        episode.update(meta)
        if "deformation_ratio" in ev:
            episode["r_max"] = float(ev["deformation_ratio"].max())

    def close(self, close_env: bool = True) -> None:
        """Flush and write the files; ``close_env=False`` keeps the env open (one file per episode)."""
        if close_env:
            super().close()
            return
        inner = self.env
        self.env = _NoClose(inner)
        try:
            super().close()
        finally:
            self.env = inner


GZIP = {"compression": "gzip", "compression_opts": 4}  # lossless and deterministic


def binary_gripper_column(values: np.ndarray, control_mode: str) -> np.ndarray:
    """Gripper actions of ``control_mode`` as its ``_binary`` twin's commands: "close" for any
    commanded closure > 0 (``pd_ee_pose``: 1 / 0; ManiSkill's modes: -1 / 1)."""
    if not normalized_gripper(control_mode):
        return (values > 0.0).astype(values.dtype)  # the paper's closure, as it always was recorded
    binary_mode = f"{control_mode.removesuffix('_binary')}_binary"
    return gripper_action(action_closure(values, control_mode), binary_mode).astype(values.dtype)


def _gzip_large_datasets(group) -> None:
    """Rewrite the group's large uncompressed datasets (the FEM state: ~2 MB an episode) with gzip:
    RecordEpisode compresses only images. Values and dtypes are unchanged."""
    for key in list(group.keys()):
        item = group[key]
        if isinstance(item, h5py.Group):
            _gzip_large_datasets(item)
        elif item.size > 4096 and item.compression is None:
            data = item[()]
            del group[key]
            group.create_dataset(key, data=data, **GZIP)


class _NoClose:
    """Stands in for the wrapped env while RecordEpisode closes its files but not the env."""

    def __init__(self, env):
        self._env = env

    def close(self):
        pass

    def __getattr__(self, name):
        return getattr(self._env, name)


@contextmanager
def quiet_maniskill_logger(level=logging.WARNING):
    """ManiSkill's logger above INFO for a block (its tools log every file they touch)."""
    old = logger.level
    logger.setLevel(level)
    try:
        yield
    finally:
        logger.setLevel(old)


def episode_paths(h5_path: Path) -> tuple[Path, Path]:
    """A trajectory file and its json (ManiSkill pairs them by name)."""
    h5_path = Path(h5_path)
    return h5_path, h5_path.with_suffix(".json")
