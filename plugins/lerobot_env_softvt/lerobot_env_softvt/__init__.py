"""``lerobot-eval --env.type=softvt``: SoftVT tasks in LeRobot's evaluation, scored as SoftVT scores them.

    lerobot-eval --policy.path=outputs/train/dp/checkpoints/last/pretrained_model \\
        --env.type=softvt --env.task=SoftVTObjectSoft-v1 --env.task_ids='[3]' \\
        --eval.n_episodes=10 --eval.batch_size=1 --policy.device=cpu

``lerobot-eval``'s success rate is task success (TSR). Every episode's SoftVT record (R_max against
the calibration card, DSR, collapsed tets, how it ended) goes to ``<output_dir>/softvt/``, with the
report and R_t plot beside it, where ``python -m mani_skill_softvt.evaluate --rescore`` and the
report tools read it; evaluations during ``lerobot-train`` (``--env.type=softvt``) leave theirs in
``<output_dir>/eval/softvt_<k>/``, one folder per evaluation. The env is
:class:`mani_skill_softvt.integrations.lerobot.env.LeRobotEnv`; this module only tells LeRobot how to
build it. The envs of a batch step one after another in LeRobot's process (a SyncVectorEnv):
each is a CPU physics job of its own, and a worker process per (task, condition, batch slot),
started up front, would cost more than it saves.
"""

from __future__ import annotations

import hashlib
import inspect
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import gymnasium as gym
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.configs.eval import EvalPipelineConfig
from lerobot.configs.train import TrainPipelineConfig
from lerobot.envs.configs import EnvConfig
from lerobot.envs.utils import freeze_after_episode_end
from lerobot.utils.constants import ACTION

from mani_skill_softvt.integrations.lerobot.export import FPS, frame_feature_shapes
from mani_skill_softvt.data.seeds import ID_EPISODES_PER_TASK
from mani_skill_softvt.integrations.lerobot.env import LeRobotEnv, records_path, suite_of_env_id
from mani_skill_softvt.evaluation.records import read_records
from mani_skill_softvt.contracts.observations import parse_image_size
from mani_skill_softvt.tasks.suites import NUM_TASKS, OOD_CONDITIONS

__all__ = ["SoftVTEnvConfig"]


def _env_key(feature: str) -> str:
    """The env's key of an export feature, as LeRobot's ``features`` name it."""
    if feature.startswith("observation.images."):
        return "pixels/" + feature.removeprefix("observation.images.")
    return "agent_pos" if feature == "observation.state" else feature.removeprefix("observation.")


def _running_pipeline() -> EvalPipelineConfig | TrainPipelineConfig | None:
    """The config of the ``lerobot-eval`` or ``lerobot-train`` run that is building these envs.

    LeRobot hands an env config nothing of its run, so its output directory (where the records
    belong), its seed and episode count (which episodes it counts) and its policy (which the records
    name) are read from the pipeline config that ``eval_main`` or the trainer holds while it makes
    the envs, one of this call's callers."""
    frame = inspect.currentframe()
    while frame is not None:
        for value in frame.f_locals.values():
            if isinstance(value, (EvalPipelineConfig, TrainPipelineConfig)):
                return value
        frame = frame.f_back
    return None


def _records_dir(run, default: str | None) -> Path:
    """``<output_dir>/softvt`` of a ``lerobot-eval`` run; ``<output_dir>/eval/softvt_<k>`` for the
    k-th evaluation of a ``lerobot-train`` run; ``default`` (``--env.records_dir``) first."""
    if default:
        return Path(default)
    if run is None or not run.output_dir:
        return Path("outputs") / "softvt"
    if isinstance(run, EvalPipelineConfig):
        return Path(run.output_dir) / "softvt"
    k = 1 + len(list((Path(run.output_dir) / "eval").glob("softvt_*")))
    return Path(run.output_dir) / "eval" / f"softvt_{k}"


def _policy_identity(run) -> tuple[str, str | None]:
    """(how the records name the policy, the SHA-256 of its weights file if there is one)."""
    if isinstance(run, TrainPipelineConfig):
        return f"lerobot:{run.policy.type}@{run.output_dir} (in training)", None
    policy = None if run is None else run.policy
    if policy is None:
        return "lerobot", None
    path = getattr(policy, "pretrained_path", None)
    spec = f"lerobot:{policy.type}" + (f"@{path}" if path else "")
    weights = Path(path) / "model.safetensors" if path else None
    if weights is None or not weights.is_file():
        return spec, None
    digest = hashlib.sha256()
    with open(weights, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return spec, digest.hexdigest()


@EnvConfig.register_subclass("softvt")
@dataclass
class SoftVTEnvConfig(EnvConfig):
    """A SoftVT suite (``task``: its env id), some of its tasks, one protocol.

    ``protocol``: ``id`` (the held-out initial states) or ``ood`` (each of ``conditions``, default
    all nine, from the same states); ``--seed=0`` starts at the protocol's first episode.
    ``obs_type``: ``state_dict``, ``rgb``, ``rgb+tactile``, ``rgbd`` or ``rgbd+tactile`` (the export's feature
    modes, :data:`mani_skill_softvt.integrations.lerobot.export.FEATURE_OBS_MODES`; rgbd adds ``observation.depth.<camera>``,
    float32 metres); ``camera_size``: ``HxW`` the cameras
    render at (the demos' ``render --camera-size``, e.g. ``84x84``) or ``native`` (224x224);
    ``image_size``: what every image stream is resized to, as the export's ``--image-size`` did
    (default 224x224, the export's; ``native`` keeps each stream's size). ``records_dir``: where the
    SoftVT records go (default: the run's ``<output_dir>/softvt``).
    """

    task: str = "SoftVTObjectSoft-v1"
    task_ids: list[int] | None = None
    protocol: str = "id"
    conditions: list[str] | None = None
    fps: int = FPS
    obs_type: str = "rgb+tactile"
    camera_size: str = "native"
    image_size: str = "224x224"
    control_mode: str = "pd_ee_pose"
    records_dir: str | None = None
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(7,))})
    features_map: dict[str, str] = field(default_factory=lambda: {ACTION: ACTION})

    def __post_init__(self):
        self.suite = suite_of_env_id(self.task)
        if self.protocol not in ("id", "ood"):
            raise ValueError(f"--env.protocol={self.protocol}: choose id or ood")
        if self.protocol == "id" and self.conditions:
            raise ValueError("--env.conditions applies to --env.protocol=ood")
        unknown = [c for c in self.conditions or () if c not in OOD_CONDITIONS]
        if unknown:
            raise ValueError(f"--env.conditions: unknown {unknown}; choose from {sorted(OOD_CONDITIONS)}")
        bad = [t for t in self.task_ids or () if not 0 <= int(t) < NUM_TASKS]
        if bad:
            raise ValueError(f"--env.task_ids: {bad} out of range; tasks are 0 to {NUM_TASKS - 1}")
        self.render_size = parse_image_size(self.camera_size, "--env.camera_size")
        self.resize_to = parse_image_size(self.image_size, "--env.image_size")
        for name, shape in frame_feature_shapes(self.obs_type, self.render_size, self.resize_to).items():
            kind = FeatureType.VISUAL if name.startswith("observation.images.") else FeatureType.STATE
            self.features[_env_key(name)] = PolicyFeature(type=kind, shape=shape)
            self.features_map[_env_key(name)] = name

    @property
    def gym_kwargs(self) -> dict:
        return {"obs_mode": self.obs_type, "control_mode": self.control_mode, "camera_size": self.render_size,
                "image_size": self.resize_to}

    def create_envs(self, n_envs: int, use_async_envs: bool = False) -> dict[str, dict[int, gym.vector.VectorEnv]]:
        """``{suite: {task_id: env}}`` for the ID protocol, ``{suite/condition: {...}}`` for OOD, so
        LeRobot's per-group numbers are per condition. Refuses a records file that already holds
        records (a second run into the same output directory): nothing is overwritten."""
        run = _running_pipeline()
        spec, sha = _policy_identity(run)
        first_seed = 0 if run is None or run.seed is None else int(run.seed)
        counted = None if run is None else int(run.eval.n_episodes)
        if counted is not None and counted > ID_EPISODES_PER_TASK:
            raise ValueError(f"--eval.n_episodes={counted}: the protocol has {ID_EPISODES_PER_TASK} episodes a task "
                             "(and condition); ask for at most that many")
        name = spec.split("@")[0].replace(":", "-")
        records = records_path(_records_dir(run, self.records_dir), self.suite, self.protocol, name)
        if records.exists() and read_records(records):
            raise FileExistsError(f"{records} already holds SoftVT records of an earlier run; give lerobot-eval "
                                  "another --output_dir (or --env.records_dir), or move that file away")
        conditions = ["id"] if self.protocol == "id" else list(self.conditions or OOD_CONDITIONS)
        tasks = [int(t) for t in self.task_ids] if self.task_ids else list(range(NUM_TASKS))
        envs: dict[str, dict[int, gym.vector.VectorEnv]] = {}
        for condition in conditions:
            group = self.suite if condition == "id" else f"{self.suite}/{condition}"
            envs[group] = {}
            for t in tasks:
                make = partial(LeRobotEnv, self.suite, t, self.protocol, None if condition == "id" else condition,
                               records=records, policy_spec=spec, policy_sha256=sha, first_seed=first_seed,
                               recorded_episodes=counted, **self.gym_kwargs)
                envs[group][t] = gym.vector.SyncVectorEnv([freeze_after_episode_end(make) for _ in range(n_envs)],
                                                          autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
        return envs
