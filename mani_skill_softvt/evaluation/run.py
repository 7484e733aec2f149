"""What one evaluation run is, resolved once: :class:`RunConfig`.

The policy (resolved through the door, :func:`~mani_skill_softvt.evaluation.policies.resolve_policy`:
its kind, its file's hash, the modes and camera size it needs), the obs and control modes and
camera size it runs with, and the episodes: suite, protocol, tasks, episodes per task, OOD
conditions. :meth:`RunConfig.resolve` builds it from what a command line or a caller gives,
validates it there (each error names the bad value and what to give instead) and fills in the
defaults; the frozen object is then passed whole to the workers, ``--reproduce``, the OOD
branch, the videos and the baselines' studies, none of which works a setting out again.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path

from ..data.seeds import ID_EPISODES_PER_TASK
from ..contracts.observations import DEFAULT_OBS_MODE, NATIVE_CAMERA_SIZE, ObsMode, camera_sensor_configs, is_native_camera_size
from ..contracts.actions import CONTROL_MODES
from ..tasks.suites import NUM_TASKS, SUITES
from .policies import PolicySource, resolve_policy
from .protocols import episodes

# The modes are the env's, declared once: every obs mode it supports (observations.ObsMode, what the
# env parses its obs_mode with) and every control mode it offers (tasks/robot.py), the gripper in each
# mode's encoding.
DEFAULT_TASKS = (0, 3, 8)


def policy_tag(spec: str) -> str:
    """A file-name-safe name of a policy spec: a trained baseline by its run directory
    (``vo-c-cpu``), a snapshot or an exported policy by its file (``vo-c-cpu_step003000``); a
    ``ws://host:port`` or ``module:Class`` with its punctuation replaced."""
    source = str(spec)
    if source.endswith(".pt"):
        source = Path(spec).parent.name if Path(spec).name == "policy.pt" else Path(spec).stem
    return re.sub(r"[^A-Za-z0-9-]+", "_", source).strip("_")


def records_stem(suite: str, protocol: str, spec: str) -> str:
    """The stem of an evaluation's files (records, report, plots): ``<suite>_<protocol>_<policy tag>``."""
    return f"{suite}_{protocol}_{policy_tag(spec)}"


def recorded_camera_size(obs_mode: str, camera_size: tuple[int, int] | None) -> list[int] | None:
    """The ``camera_size`` a record of a run in ``obs_mode`` carries: the cameras' (height, width),
    the native 224x224 unless asked otherwise; None in obs modes without images."""
    return [int(v) for v in (camera_size or NATIVE_CAMERA_SIZE)] if ObsMode.parse(obs_mode).images else None


def task_ids(tasks) -> tuple[int, ...]:
    """Task ids as a command takes them (``all``, or ids as numbers or strings), checked against the suites'."""
    if tasks in ("all", ["all"], ("all",)):
        return tuple(range(NUM_TASKS))
    try:
        ids = tuple(int(t) for t in tasks)
    except (TypeError, ValueError):
        ids = ()
    if not ids or any(not 0 <= t < NUM_TASKS for t in ids):
        raise ValueError(f"task ids must be in [0, {NUM_TASKS - 1}] or 'all', got {list(tasks)}")
    return ids


@dataclass(frozen=True)
class RunConfig:
    """One evaluation run (module docstring). Build it with :meth:`resolve`."""

    policy: PolicySource
    obs_mode: str
    control_mode: str
    camera_size: tuple[int, int] | None  # the cameras' (height, width); None: native
    suite: str = "object_soft"
    protocol: str = "id"
    tasks: tuple[int, ...] = DEFAULT_TASKS
    episodes_per_task: int = 1
    conditions: tuple[str, ...] | None = None  # OOD conditions (None: all nine)

    @classmethod
    def resolve(cls, policy: str | PolicySource = "expert", obs_mode: str | None = None,
                control_mode: str | None = None, camera_size: tuple[int, int] | None = None,
                suite: str = "object_soft", protocol: str = "id", tasks=DEFAULT_TASKS,
                episodes_per_task: int = 1, conditions=None) -> RunConfig:
        """The run, validated; ValueError naming the value that cannot be (the CLI prints it)."""
        source = policy if isinstance(policy, PolicySource) else resolve_policy(policy)
        spec = source.spec
        obs_mode = obs_mode or (source.obs_modes or (DEFAULT_OBS_MODE,))[0]  # the policy's first, or the env's
        control_mode = control_mode or (source.control_modes or ("pd_ee_pose",))[0]
        try:
            ObsMode.parse(obs_mode)
        except ValueError as e:
            raise ValueError(f"--obs-mode {e}") from None
        if control_mode not in CONTROL_MODES:
            raise ValueError(f"--control-mode {control_mode}: choose one of {', '.join(CONTROL_MODES)}")
        for flag, given, allowed in (("--obs-mode", obs_mode, source.obs_modes),
                                     ("--control-mode", control_mode, source.control_modes)):
            if allowed and given not in allowed:
                need = " or ".join(allowed)
                raise ValueError(f"{spec} runs with {flag} {need}, not {given}; evaluate it with {flag} {need} "
                                 "(or leave the flag out)" if source.kind != "remote" else
                                 f"a policy server gets camera images: use {flag} {need}, not '{given}'")
        if camera_size is not None:
            camera_size = tuple(int(v) for v in camera_size)
            if source.camera_size is not None and camera_size != source.camera_size:
                h, w = source.camera_size
                raise ValueError(f"policy {spec} was trained on {h}x{w} cameras; evaluate it at that size (leave "
                                 f"camera_size out), not {camera_size[0]}x{camera_size[1]}")
        camera_size = camera_size or source.camera_size
        if is_native_camera_size(camera_size):
            camera_size = None
        camera_sensor_configs(camera_size)  # a size too small is an error here, naming it, not in a worker
        if suite not in SUITES:
            raise ValueError(f"suite '{suite}': choose one of {sorted(SUITES)}")
        frames = SUITES[suite].frames_tactile_model(obs_mode)
        if source.tactile_model is not None and frames is not None and frames != source.tactile_model:
            # Soft and rigid suites render touch in different models (tactile.constants.model_version).
            raise ValueError(f"policy {spec} learned from tactile frames of model {source.tactile_model}, and suite "
                             f"{suite} renders model {frames}: evaluate it on a suite of its model, or train one "
                             f"on {suite}'s demos")
        tasks = task_ids(tasks)
        if int(episodes_per_task) < 1:
            raise ValueError(f"episodes per task must be >= 1 (the protocol has {ID_EPISODES_PER_TASK} a task), "
                             f"got {episodes_per_task}")
        run = cls(source, obs_mode, control_mode, camera_size, suite, protocol, tasks, int(episodes_per_task),
                  None if conditions is None else tuple(conditions))
        run.episodes()  # an unknown protocol or condition, or OOD on a rigid suite, is refused here
        return run

    def episodes(self) -> list[dict]:
        """The run's (suite, task_id, condition, seed) list, in the protocol's order."""
        return episodes(self.suite, self.protocol, self.tasks, self.episodes_per_task, self.conditions)

    def with_protocol(self, protocol: str) -> RunConfig:
        """The same policy and settings under another protocol (the ID records an OOD run is read against)."""
        return replace(self, protocol=protocol, conditions=None)

    @property
    def stem(self) -> str:
        """The stem of the run's files: ``<suite>_<protocol>_<policy tag>``."""
        return records_stem(self.suite, self.protocol, self.policy.spec)

    def record_fields(self) -> dict:
        """What names the run in each of its records (resume matches on these, and on
        ``policy_sha256``, which only a policy file's records carry)."""
        return {"policy": self.policy.spec, "obs_mode": self.obs_mode, "control_mode": self.control_mode,
                "tactile_model": SUITES[self.suite].frames_tactile_model(self.obs_mode),
                "camera_size": recorded_camera_size(self.obs_mode, self.camera_size)}
