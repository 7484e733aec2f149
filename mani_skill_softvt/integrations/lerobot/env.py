"""A SoftVT task as LeRobot's evaluation loop (``lerobot-eval``) drives an env, scored as ours.

LeRobot runs its own rollout loop over gymnasium vector envs: it resets each sub-env with a seed,
converts the observation with ``preprocess_observation`` (``pixels`` -> ``observation.images.*``,
``agent_pos`` -> ``observation.state``, any other array ``k`` -> ``observation.k``), steps with one
action a step, and counts ``info["is_success"]``. :class:`LeRobotEnv` is that env for one SoftVT
task, and nothing of LeRobot is imported here (the plugin, ``lerobot_env_softvt``, registers the
``EnvConfig`` that builds it):

- **Observations** carry the LeRobot export's feature names
  (:func:`~mani_skill_softvt.integrations.lerobot.export.frame_features`), so a policy trained on the export runs
  unchanged: the cameras and GelSight images as ``pixels``, proprioception as ``agent_pos``, the
  marker fields as ``tactile.<side>.<field>``. Nothing evaluator-only is among them.
- **Seeds name protocol episodes**: ``reset(seed=s)`` starts episode ``s mod 50`` of the task
  under the protocol (the ID protocol's held-out initial states, or the OOD condition's from the
  same states), so ``lerobot-eval --eval.n_episodes=N`` with its default seed (1000) or ``--seed=0``
  runs the protocol's first N episodes, the episodes ``evaluate --episodes-per-task N`` runs.
  LeRobot runs whole batches and drops the episodes past N: those (``recorded_episodes``) reset
  and end at once, unrecorded.
- **Scoring** is the evaluator's: every step's ``info`` holds ``is_success`` (task success, what
  ``lerobot-eval`` counts as its success rate, our TSR) and the DSR wrapper's R_t, R_max,
  collapsed tets and ``dsr_success``; when the episode ends, ``termination`` says how and the
  episode's standard record is appended to ``records`` (the file ``evaluate --rescore`` and the
  report tools read), and ``close`` writes the report beside it.
- **A misbehaving policy is a result**: an action that is not 7 finite numbers ends the episode as
  ``policy_error``, a blown-up FEM as ``sim_unstable``; both are recorded and the run goes on.
"""

from __future__ import annotations

import time
from pathlib import Path

import gymnasium as gym
import numpy as np

from .export import FPS, frame_feature_shapes, frame_features
from ...data.seeds import ID_EPISODES_PER_TASK
from ...fileio import append_jsonl
from ...contracts.observations import flatten_batch, info_bool, unbatch
from ...physics.errors import SimulationInstabilityError
from ...rollout import episode_end
from ...tasks.constants import MAX_EPISODE_STEPS
from ...tasks.suites import SUITES, task_spec
from ...evaluation.protocols import episodes
from ...evaluation.records import read_records
from ...evaluation.report import plot_traces, write_report
from ...evaluation.run import records_stem
from ...evaluation.runner import episode_record
from ...evaluation.wrapper import make_env

IMAGE_PREFIX, STATE_FEATURE = "observation.images.", "observation.state"


def suite_of_env_id(env_id: str) -> str:
    """The suite whose env id is ``env_id`` (``SoftVTObjectSoft-v1`` -> ``object_soft``)."""
    for name, suite in SUITES.items():
        if suite.env_id == env_id:
            return name
    raise ValueError(f"unknown SoftVT env id {env_id!r}; choose one of {sorted(s.env_id for s in SUITES.values())}")


def lerobot_observation(features: dict[str, np.ndarray]) -> dict:
    """The export's features as LeRobot's env keys: images under ``pixels``, ``observation.state``
    as ``agent_pos``, every other ``observation.k`` as ``k`` (LeRobot adds the prefix back)."""
    out: dict = {"pixels": {}}
    for name, value in features.items():
        if name.startswith(IMAGE_PREFIX):
            out["pixels"][name[len(IMAGE_PREFIX):]] = value
        elif name == STATE_FEATURE:
            out["agent_pos"] = value
        else:
            out[name[len("observation."):]] = value
    if not out["pixels"]:
        del out["pixels"]
    return out


def observation_space(obs_mode: str, camera_size: tuple[int, int] | None,
                      image_size: tuple[int, int] | None = None) -> gym.spaces.Dict:
    """The space of :func:`lerobot_observation` in ``obs_mode``: images uint8, the rest float32."""
    shapes = frame_feature_shapes(obs_mode, camera_size, image_size)

    def box(name, shape):
        image = name.startswith(IMAGE_PREFIX)
        return gym.spaces.Box(0, 255, shape, np.uint8) if image else gym.spaces.Box(-np.inf, np.inf, shape, np.float32)

    tree = lerobot_observation({name: box(name, shape) for name, shape in shapes.items()})
    return gym.spaces.Dict({k: gym.spaces.Dict(v) if isinstance(v, dict) else v for k, v in tree.items()})


class LeRobotEnv(gym.Env):
    """One SoftVT task under one protocol, as ``lerobot-eval`` steps it (module docstring).

    ``camera_size`` is what the cameras render at (the demos' ``render --camera-size``),
    ``image_size`` what every image is then resized to (the export's ``--image-size``; None: not
    resized). ``records``: the JSONL file each finished episode's record is appended to (None:
    none kept). ``first_seed`` / ``recorded_episodes``: the run's first seed and how many
    episodes it counts (seeds past them are LeRobot's batch padding).
    ``policy_spec`` / ``policy_sha256`` name the policy in the records (LeRobot's pretrained path
    and the hash of its weights); the policy itself is never seen here.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": FPS}

    def __init__(self, suite: str = "object_soft", task_id: int = 0, protocol: str = "id",
                 condition: str | None = None, obs_mode: str = "rgb+tactile", control_mode: str = "pd_ee_pose",
                 camera_size: tuple[int, int] | None = None, image_size: tuple[int, int] | None = None,
                 records: str | Path | None = None, policy_spec: str = "lerobot", policy_sha256: str | None = None,
                 first_seed: int = 0, recorded_episodes: int | None = None, render_mode: str = "rgb_array"):
        if protocol not in ("id", "ood"):  # the side swap and the difficulty study run through evaluate
            raise ValueError(f"protocol {protocol!r}: lerobot-eval runs 'id' or 'ood'; run {protocol} with "
                             "softvt-evaluate --protocol")
        if protocol == "ood" and condition is None:
            raise ValueError("the OOD protocol runs one condition per env: give condition (e.g. 'mass_x2.5')")
        self.suite, self.task_id, self.protocol = suite, int(task_id), protocol
        self.condition = "id" if protocol == "id" else condition
        self._episodes = episodes(suite, protocol, [self.task_id], ID_EPISODES_PER_TASK,
                                  None if protocol == "id" else [condition])
        self.records = None if records is None else Path(records)
        self.policy_spec, self.policy_sha256 = policy_spec, policy_sha256
        self.first_seed, self.recorded_episodes = int(first_seed), recorded_episodes
        self.render_mode = render_mode
        # render_mode: LeRobot's videos are the human-view camera's frames (env.render()).
        self._make = dict(obs_mode=obs_mode, control_mode=control_mode, camera_size=camera_size,
                          render_mode=render_mode)
        self.image_size = None if image_size is None else tuple(image_size)
        self.observation_space = observation_space(obs_mode, camera_size, self.image_size)
        self.action_space = gym.spaces.Box(-np.inf, np.inf, (7,), np.float32)
        self._max_episode_steps = MAX_EPISODE_STEPS  # LeRobot's loop reads this name
        self._env = None  # built at the first reset and let go at close: LeRobot makes every task's env
        self._next_index = 0  # before it runs any, and closes each once its episodes are done
        self._ended, self._obs = None, {}

    def _sim(self):
        if self._env is None:
            self._env = make_env(self.suite, self.task_id, **self._make)
        return self._env

    # LeRobot reads the instruction as `task_description` (or `task`), through env.call.
    @property
    def task_description(self) -> str:
        return task_spec(self.suite, self.task_id).instruction

    @property
    def task(self) -> str:
        return self.task_description

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is None:  # no seeds given: the protocol's episodes in order
            seed = self.first_seed + self._next_index
        seed = int(seed)
        if seed < 0:
            raise ValueError(f"seed {seed}: SoftVT seeds name protocol episodes (seed mod {len(self._episodes)}); "
                             "give lerobot-eval a seed >= 0 (its default, 1000, or 0 start at the first)")
        self._next_index = seed - self.first_seed + 1
        self._episode = self._episodes[seed % len(self._episodes)]
        opts = {} if self.condition == "id" else {"ood": self.condition}
        obs, info = self._sim().reset(seed=int(self._episode["seed"]), options=opts)
        self._steps, self._t0, self._ended = 0, time.perf_counter(), None
        self._obs = lerobot_observation(frame_features(flatten_batch(obs), self.image_size))
        info = self._info(info)
        if self.recorded_episodes is not None and not 0 <= seed - self.first_seed < self.recorded_episodes:
            # LeRobot's batch padding: it drops this episode, so it ends at once and leaves no record.
            self._ended = {**info, "termination": "padding"}
        return self._obs, info

    def step(self, action):
        if self._ended is not None:  # LeRobot may step a finished sub-env; it changes nothing
            return self._obs, 0.0, True, False, self._ended
        try:
            a = self._env.unwrapped.validate_action(np.asarray(action))
        except ValueError as e:
            return self._end("policy_error", f"ValueError in the action: {e}", self._last_info)
        try:
            obs, reward, terminated, truncated, info = self._env.step(a)
        except SimulationInstabilityError as e:
            return self._end("sim_unstable", str(e), self._last_info)
        self._steps += 1
        self._obs = lerobot_observation(frame_features(flatten_batch(obs), self.image_size))
        info = self._info(info)
        termination = episode_end("episode", terminated, truncated, info)
        if termination is not None:
            return self._end(termination, None, info, float(reward))
        return self._obs, float(reward), False, False, info

    def _info(self, info: dict) -> dict:
        """The scoring as plain values (LeRobot stacks them across sub-envs)."""
        self._raw_info = info
        out = {"is_success": bool(info["task_success"]), "task_success": bool(info["task_success"]),
               "dsr_success": bool(info["dsr_success"]), "deformation_ratio": float(info["deformation_ratio"]),
               "r_max": float(info["r_max"]), "collapsed_tets": int(info["collapsed_tets"]),
               "collapsed_steps": int(info["collapsed_steps"]),
               "dropped": info_bool(info, "dropped"), "termination": ""}
        self._last_info = out
        return out

    def _end(self, termination: str, error: str | None, info: dict, reward: float = 0.0):
        rec = episode_record(self._env, self._episode, termination=termination, error=error, steps=self._steps,
                             info=self._raw_info, policy_name="lerobot", policy_spec=self.policy_spec,
                             policy_sha256=self.policy_sha256, wall_s=time.perf_counter() - self._t0)
        if self.records is not None:
            append_jsonl(self.records, rec)
        self._ended = {**info, "is_success": rec["success"], "dsr_success": rec["dsr_success"],
                       "termination": termination}
        # Ended by the env itself (success, drop, step limit): terminated unless the limit came first.
        return self._obs, reward, termination != "timeout", termination == "timeout", self._ended

    def render(self):
        """The human-view camera's frame (LeRobot's episode videos), uint8 (H, W, 3)."""
        return np.asarray(unbatch(self._sim().render()), dtype=np.uint8)

    def close(self):
        if self.records is not None and self.records.exists():
            records = read_records(self.records)
            if records:
                stem = self.records.stem
                write_report(records, self.records.parent, stem)
                plot_traces(records, self.records.parent / f"{stem}_traces.png")
        if self._env is not None:
            self._env.close()
            self._env = None


def records_path(records_dir: str | Path, suite: str, protocol: str, policy_name: str) -> Path:
    """Where a LeRobot run's records go: ``<records_dir>/<suite>_<protocol>_<policy name>.jsonl``
    (the run's directory names the run; the records name the policy's path and hash)."""
    return Path(records_dir) / f"{records_stem(suite, protocol, policy_name)}.jsonl"
