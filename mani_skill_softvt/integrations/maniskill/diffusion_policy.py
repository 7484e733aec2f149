"""A checkpoint of ManiSkill's own diffusion-policy baseline as a policy of the evaluation.

ManiSkill's ``examples/baselines/diffusion_policy/train_rgbd.py`` (``rgb``) and ``train.py``
(``state``), trained on a converted SoftVT demo (docs/maniskill.md), save
``runs/<run>/checkpoints/<tag>.pt``. :class:`ManiSkillDiffusionPolicy` runs such a checkpoint in
``python -m mani_skill_softvt.evaluate``, scored like every other policy (TSR, DSR, R_t)::

    SOFTVT_MANISKILL_DP_DIR=~/ManiSkill/examples/baselines/diffusion_policy \\
    SOFTVT_MANISKILL_DP_CHECKPOINT=runs/softvt_rgb/checkpoints/best_eval_success_once.pt \\
    python -m mani_skill_softvt.evaluate --policy mani_skill_softvt.evaluation.maniskill_dp:ManiSkillDiffusionPolicy \\
        --tasks 3 --obs-mode rgb --control-mode pd_ee_delta_pose

The policy is ManiSkill's own ``Agent`` (imported from the script in ``SOFTVT_MANISKILL_DP_DIR``;
nothing of ManiSkill's baseline is copied here) with the checkpoint's EMA weights, the ones the
script evaluates. ``SOFTVT_MANISKILL_DP_ARGS`` passes the script's model flags if the run used
others than their defaults (``"--obs-horizon 2 --act-horizon 8 --pred-horizon 16"``). The
observations are what the script's evaluation env gives the agent: ``FlattenRGBDObservationWrapper``
(rgb: the cameras' images side by side in channels, state: ``agent`` then ``extra`` flattened)
stacked over the last ``obs_horizon`` steps, the first repeated at the reset (ManiSkill's
``FrameStack``). To see those steps, a chunk of ``act_horizon`` actions is handed out as its first
``act_horizon - obs_horizon + 1`` rows, then one row a call, so the next prediction reads the
frames of consecutive steps, as in the script. The DDPM noise is seeded with the episode seed.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import shlex
import sys
from collections import deque
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch
from gymnasium import spaces
from mani_skill.utils.common import flatten_state_dict, to_numpy

from ...contracts.policy import Policy

SCRIPTS = {"rgb": "train_rgbd.py", "state": "train.py"}  # obs mode -> ManiSkill's script that trains in it


def _env_path(var: str) -> Path:
    value = os.environ.get(var)
    if not value:
        raise ValueError(f"{var} is not set: " + {
            "SOFTVT_MANISKILL_DP_DIR": "point it at ManiSkill's examples/baselines/diffusion_policy (the folder "
                                       "holding train_rgbd.py)",
            "SOFTVT_MANISKILL_DP_CHECKPOINT": "point it at the run's checkpoint, runs/<run>/checkpoints/<tag>.pt"}[var])
    path = Path(value).expanduser()
    if not path.exists():
        raise ValueError(f"{var}={value}: no such file or folder")
    return path


def load_script(dp_dir: Path, script: str):
    """ManiSkill's training script as a module (its ``Agent`` and ``Args``; its ``__main__`` block does
    not run), with its ``diffusion_policy`` package importable as the script itself imports it."""
    path = Path(dp_dir) / script
    if not path.exists():
        raise ValueError(f"{path} does not exist: SOFTVT_MANISKILL_DP_DIR must be ManiSkill's "
                         f"examples/baselines/diffusion_policy")
    if str(dp_dir) not in sys.path:
        sys.path.insert(0, str(dp_dir))
    name = f"maniskill_dp_{path.stem}_{hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:12]}"  # one per script file
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


def flatten_observation(obs) -> dict[str, np.ndarray]:
    """One step's observation (the env's batch of one) as the script's evaluation env gives it to
    the agent, unstacked: ``{"state": (D,), "rgb": (H, W, 3 * cameras)}`` in ``rgb``, ``{"state": (D,)}``
    in ``state`` (ManiSkill's ``FlattenRGBDObservationWrapper`` / the flat state)."""
    if not isinstance(obs, dict):
        return {"state": np.asarray(to_numpy(obs), np.float32).reshape(-1)}
    if "tactile" in obs:
        raise ValueError("ManiSkill's diffusion-policy scripts train on rgb or state observations: evaluate the "
                         "checkpoint with --obs-mode rgb (or state for train.py's)")
    rest = {k: v for k, v in obs.items() if k not in ("sensor_data", "sensor_param")}
    state = np.asarray(to_numpy(flatten_state_dict(rest, use_torch=True)), np.float32)[0]
    rgb = np.concatenate([np.asarray(to_numpy(cam["rgb"]))[0] for cam in obs["sensor_data"].values()], axis=-1)
    return {"state": state, "rgb": rgb}


class ManiSkillDiffusionPolicy(Policy):
    """A checkpoint of ManiSkill's diffusion-policy baseline (module docstring). Paths from
    ``SOFTVT_MANISKILL_DP_DIR`` and ``SOFTVT_MANISKILL_DP_CHECKPOINT``, or a subclass's
    ``dp_dir`` / ``checkpoint``."""

    name = "maniskill_dp"
    obs_modes = ("rgb", "state")  # what the evaluation offers it (the first: its default)
    control_modes = ("pd_ee_delta_pose", "pd_joint_delta_pos")  # the baseline's delta modes
    dp_dir: str | None = None
    checkpoint: str | None = None

    def __init__(self):
        self.dp_dir_path = Path(self.dp_dir) if self.dp_dir else _env_path("SOFTVT_MANISKILL_DP_DIR")
        self.checkpoint_path = Path(self.checkpoint) if self.checkpoint else _env_path("SOFTVT_MANISKILL_DP_CHECKPOINT")
        self.name = f"maniskill_dp[{self.checkpoint_path.parent.parent.name}/{self.checkpoint_path.name}]"
        self.agent = None  # built at the first observation, which tells the obs mode and the spaces
        self.frames = None
        self.pending: list[np.ndarray] = []

    def _build(self, frame: dict[str, np.ndarray]) -> None:
        mode = "rgb" if "rgb" in frame else "state"
        module = load_script(self.dp_dir_path, SCRIPTS[mode])
        args = module.tyro.cli(module.Args, args=shlex.split(os.environ.get("SOFTVT_MANISKILL_DP_ARGS", "")))
        h = args.obs_horizon
        if mode == "rgb":
            observation_space = spaces.Dict({
                "state": spaces.Box(-np.inf, np.inf, (h, *frame["state"].shape), np.float32),
                "rgb": spaces.Box(0, 255, (h, *frame["rgb"].shape), np.uint8)})
        else:
            observation_space = spaces.Box(-np.inf, np.inf, (h, *frame["state"].shape), np.float32)
        try:
            weights = torch.load(self.checkpoint_path, map_location="cpu")["ema_agent"]
            # The U-Net's last layer maps onto the action: 7 in pd_ee_delta_pose, 8 in pd_joint_delta_pos.
            dim = next((int(v.shape[0]) for k, v in weights.items() if k.endswith("final_conv.1.weight")), 7)
            action_space = spaces.Box(-1.0, 1.0, (dim,), np.float32)
            # The script's Agent reads only these two spaces of the env it is given.
            agent = module.Agent(SimpleNamespace(single_observation_space=observation_space,
                                                 single_action_space=action_space), args)
            agent.load_state_dict(weights)
        except (KeyError, RuntimeError, OSError) as e:
            raise ValueError(f"{self.checkpoint_path} is not a checkpoint of ManiSkill's {SCRIPTS[mode]} with these "
                             f"observations and SOFTVT_MANISKILL_DP_ARGS ({e}); pass the model flags the run was "
                             f"trained with in SOFTVT_MANISKILL_DP_ARGS") from None
        self.agent, self.args, self.mode = agent.eval(), args, mode
        self.frames = deque(maxlen=h)

    def reset(self, instruction: str, seed: int) -> None:
        torch.manual_seed(0 if seed is None else int(seed))
        self.pending = []
        if self.frames is not None:
            self.frames.clear()

    def act(self, obs) -> np.ndarray:
        frame = flatten_observation(obs)
        if self.agent is None:
            self._build(frame)
        if not self.frames:  # a reset: FrameStack repeats the first frame
            self.frames.extend([frame] * self.frames.maxlen)
        else:
            self.frames.append(frame)
        if self.pending:
            return self.pending.pop(0)[None]
        stacked = {k: torch.from_numpy(np.stack([f[k] for f in self.frames]))[None] for k in frame}
        with torch.no_grad():
            chunk = self.agent.get_action(stacked if self.mode == "rgb" else stacked["state"])[0].numpy()
        # Hand out the rows so that the next prediction sees the last obs_horizon steps (module docstring).
        first = len(chunk) - (self.args.obs_horizon - 1)
        self.pending = list(chunk[first:])
        return chunk[:first]
