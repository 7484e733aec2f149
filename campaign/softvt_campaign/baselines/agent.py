"""A trained Diffusion Policy baseline as an evaluation policy (``evaluate --policy <policy.pt>``).

It sees every control step's observation (``act`` returns one action at a time, so the two
observation frames it conditions on are consecutive steps, as in training) and replans every
``action_steps`` steps: it denoises a 16-step chunk and executes its first 8. Only the frames it
will plan from are read (the last ``obs_horizon`` before each replanning): for the others,
``needs_next_images`` tells the evaluator not to render the cameras (with the cpu preset's 2
frames and 8 executed actions, 2 of every 8 steps render). Its record names the
variant and its recipe (``diffusion_policy[vt-c,cpu,rgb+depth]``). The sampling noise is seeded by the episode seed, and torch
runs on one thread here, so an episode is the same bit for bit on a re-run.
"""

from __future__ import annotations

import hashlib
from collections import deque
from pathlib import Path

import numpy as np
import torch

from mani_skill_softvt.evaluation.policies import PolicyKind, PolicySource
from mani_skill_softvt.contracts.observations import flatten_batch, is_native_camera_size
from mani_skill_softvt.contracts.policy import Policy
from mani_skill_softvt.tasks.suites import get_suite
from .config import DPConfig
from .features import frame_features
from .model import DiffusionPolicyModel, noise_scheduler
from .model import empty_stats, load_checkpoint

GRIPPER = 6  # the action's gripper column


def read_policy_file(path: Path, data: bytes | None = None) -> tuple[DPConfig, dict]:
    """The config and the checkpoint of a ``policy.pt`` (its ``model`` is a state dict), from
    ``data`` if the file was already read; a clear error for anything else."""
    path = Path(path)
    if data is None:
        if not path.is_file():
            raise FileNotFoundError(f"policy checkpoint {path} does not exist; train one with "
                                    "`python -m softvt_campaign.baselines.train --variant ...` (it writes policy.pt)")
        data = path.read_bytes()
    try:
        ckpt = load_checkpoint(data, path)
    except ValueError:  # the trainer's advice (delete it, train into another --out) does not fit a policy given to run
        raise ValueError(f"{path} cannot be read as a policy file (truncated or damaged): copy it again from where "
                         "it was trained or committed, or export it again (softvt-export-policy)") from None
    if not isinstance(ckpt, dict) or "config" not in ckpt or "model" not in ckpt or "optimizer" in ckpt:
        raise ValueError(f"{path} is not a baseline policy file (policy.pt written at the end of training); "
                         "a checkpoint.pt is a training state: finish the run to get policy.pt")
    cfg = DPConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in ckpt["config"].items()})
    trained_on = ckpt.get("tactile_model") or 1  # policy files from before the version was kept: 1
    rendered = get_suite(cfg.suite).tactile_model
    if cfg.tactile and trained_on != rendered:
        raise ValueError(f"{path} was trained on tactile frames of model {trained_on}, and this package renders "
                         f"{cfg.suite}'s in model {rendered} (tactile.constants.model_version): its touch inputs "
                         "would not be what it "
                         "learned. Re-render the demos and retrain it (docs/baselines.md)")
    return cfg, ckpt


def _read_pinned(path: Path, sha256: str | None) -> bytes:
    """The bytes of a policy file, checked against the SHA-256 its run was resolved with."""
    if not Path(path).is_file():
        read_policy_file(path)  # the message that says how to get one
    data = Path(path).read_bytes()
    if sha256 is not None and hashlib.sha256(data).hexdigest() != sha256:
        raise ValueError(f"{path} changed since the evaluation started (its SHA-256 is not the one its records carry); "
                         "evaluate again once it is no longer being written")
    return data


def camera_render_size(ckpt: dict) -> tuple[int, int] | None:
    """(height, width) a policy's training cameras were rendered at, None for the native 224x224
    (policy files from before it was kept were trained on native renderings)."""
    size = ckpt.get("camera_render_size")
    return None if not size or is_native_camera_size(size) else tuple(int(v) for v in size)


def load_policy_file(path: Path, data: bytes | None = None) -> tuple[DPConfig, DiffusionPolicyModel, dict]:
    """The config, the (EMA) model, ready for inference on the CPU, and the checkpoint of a ``policy.pt``."""
    cfg, ckpt = read_policy_file(path, data)
    model = DiffusionPolicyModel(cfg, empty_stats(cfg))
    model.load_state_dict(ckpt["model"])
    model.eval()
    return cfg, model, ckpt


def policy_name(cfg: DPConfig) -> str:
    """The name in evaluation records: variant, preset, and the tactile inputs of a VT variant
    (``diffusion_policy[vt-c,cpu,rgb+depth]``), so that runs of different recipes never pool."""
    parts = [cfg.variant, cfg.preset] + ([cfg.tactile_inputs] if cfg.tactile else [])
    return f"diffusion_policy[{','.join(parts)}]"


def required_modes(cfg: DPConfig) -> tuple[str, str]:
    """(obs mode, control mode) a policy of ``cfg`` was trained for: rgb+tactile for VT variants,
    and the binary gripper control mode for the -b variants."""
    return ("rgb+tactile" if cfg.tactile else "rgb"), ("pd_ee_pose_binary" if cfg.binary_gripper else "pd_ee_pose")


class PolicyFiles(PolicyKind):
    """The trained baselines' policy files (a run's ``policy.pt``, a snapshot, an exported ``.pt``)
    as a policy kind of the evaluation (registered in ``pyproject.toml``): one read of the file
    gives its hash, the modes it was trained for and its camera size."""

    name = "diffusion_policy"

    def matches(self, spec: str) -> bool:
        return spec.endswith(".pt")

    def resolve(self, spec: str) -> PolicySource:
        return resolve_policy_file(spec)[0]

    def load(self, source: PolicySource) -> Policy:
        return DiffusionPolicyAgent(source.spec, sha256=source.sha256)


POLICY_FILES = PolicyFiles()


def resolve_policy_file(spec: str | Path) -> tuple[PolicySource, DPConfig, dict]:
    """The :class:`PolicySource` of a policy file, with its config and checkpoint, from one read."""
    data = _read_pinned(Path(spec), None)
    cfg, ckpt = read_policy_file(Path(spec), data)
    obs_mode, control_mode = required_modes(cfg)
    source = PolicySource(str(spec), PolicyFiles.name, sha256=hashlib.sha256(data).hexdigest(), obs_modes=(obs_mode,),
                          control_modes=(control_mode,), camera_size=camera_render_size(ckpt),
                          tactile_model=(ckpt.get("tactile_model") or 1) if cfg.tactile else None)
    return source, cfg, ckpt


def executed_actions(chunk: np.ndarray, cfg: DPConfig) -> np.ndarray:
    """The actions the agent sends of a denoised (..., action_horizon, 7) chunk: the first
    ``action_steps``, the gripper closure clipped to [0, 1] (thresholded at 0.5 for -b variants)."""
    out = np.asarray(chunk)[..., :cfg.action_steps, :].astype(np.float32)
    if cfg.binary_gripper:
        out[..., GRIPPER] = (out[..., GRIPPER] > 0.5).astype(np.float32)
    else:
        out[..., GRIPPER] = np.clip(out[..., GRIPPER], 0.0, 1.0)
    return out


class DiffusionPolicyAgent(Policy):
    """Closed-loop Diffusion Policy (see the module docstring)."""

    def __init__(self, path: str | Path, threads: int = 1, sha256: str | None = None):
        self.path = Path(path)
        self.cfg, self.model, ckpt = load_policy_file(self.path, _read_pinned(self.path, sha256))
        self.name = policy_name(self.cfg)
        self.camera_size = camera_render_size(ckpt)  # the evaluator renders its cameras as in training
        self.obs_mode = "rgb+tactile" if self.cfg.tactile else "rgb"  # what required_modes() says
        self.scheduler = noise_scheduler(self.cfg, inference=True)
        self.threads = threads
        self.history: deque = deque(maxlen=self.cfg.obs_horizon)
        self.queue: list[np.ndarray] = []

    def reset(self, instruction: str, seed: int) -> None:
        self.generator = torch.Generator().manual_seed(int(seed))
        self.history.clear()
        self.queue = []

    def act(self, obs) -> np.ndarray:
        if not isinstance(obs, dict) or "sensor_data" not in obs:
            raise ValueError(f"{self.name} needs camera images: evaluate with --obs-mode {self.obs_mode}")
        if self._reads_frame():  # a frame that leaves the window before the next plan is not read
            frame = frame_features(flatten_batch(obs), self.cfg)
            if not self.history:  # the first step: its own previous frame, as in training
                self.history.extend([frame] * (self.cfg.obs_horizon - 1))
            self.history.append(frame)
        if not self.queue:
            self.queue = list(self._plan())
        return self.queue.pop(0)[None]

    def _reads_frame(self) -> bool:
        """Whether the frame of this call is among the last ``obs_horizon`` before the next plan
        (the queue holds the actions left to send before it)."""
        return len(self.queue) < self.cfg.obs_horizon

    def needs_next_images(self) -> bool:
        return self._reads_frame()

    def _plan(self) -> np.ndarray:
        window = {k: torch.from_numpy(np.stack([f[k] for f in self.history]))[None] for k in self.history[0]}
        threads = torch.get_num_threads()
        torch.set_num_threads(self.threads)
        try:
            chunk = self.model.sample(window, self.generator, self.scheduler)[0].numpy()
        finally:
            torch.set_num_threads(threads)
        return executed_actions(chunk, self.cfg)
