"""Diffusion Policy (Chi et al., 2023) as the paper's baselines use it: observation features from
one image encoder per stream, the robot state (and, for VT, the marker motion), two frames of
each, condition a 1-D U-Net that denoises a chunk of normalised 7-D actions (DDPM, epsilon
prediction, squared-cosine noise schedule).

Normalisation as Diffusion Policy does it: actions, state and marker motion are mapped
min-max to [-1, 1] with the training set's ranges (a constant column is only centred), images
to [-1, 1]. The ranges are buffers of the module, so a checkpoint carries them.

With ``precision="bf16"`` the encoders and the U-Net run under ``torch.autocast`` (bfloat16
products, float32 weights); their outputs come back as float32, so the normalisers, the loss and
the sampler's arithmetic stay float32.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import torch
from diffusers import DDIMScheduler, DDPMScheduler
from torch import nn

from .config import DPConfig
from .features import image_keys
from .networks import ConditionalUnet1D, ImageEncoder

MIN_RANGE = 1e-4  # a column whose training range is smaller is centred, not scaled


def noise_scheduler(cfg: DPConfig, inference: bool = False):
    """The training noise schedule (DDPM) or the sampler used at inference (DDPM or DDIM on it)."""
    kw = dict(num_train_timesteps=cfg.train_timesteps, beta_schedule="squaredcos_cap_v2", clip_sample=True,
              prediction_type="epsilon")
    if inference and cfg.inference_scheduler == "ddim":
        return DDIMScheduler(**kw, set_alpha_to_one=True, steps_offset=0)
    return DDPMScheduler(**kw)


class RangeNormalizer(nn.Module):
    """Min-max to [-1, 1] per column, from the training data's min and max (buffers)."""

    def __init__(self, minimum: torch.Tensor, maximum: torch.Tensor):
        super().__init__()
        span = maximum - minimum
        scale = torch.where(span > MIN_RANGE, 2.0 / span.clamp_min(MIN_RANGE), torch.ones_like(span))
        offset = torch.where(span > MIN_RANGE, -1.0 - minimum * scale, -(minimum + maximum) / 2)
        self.register_buffer("scale", scale.float())
        self.register_buffer("offset", offset.float())

    def forward(self, x):
        return x * self.scale + self.offset

    def inverse(self, y):
        return (y - self.offset) / self.scale


def images_to_unit(x: torch.Tensor) -> torch.Tensor:
    """(..., H, W, C) uint8 -> (..., C, H, W) float in [-1, 1]."""
    return x.movedim(-1, -3).float() * (2.0 / 255.0) - 1.0


class DiffusionPolicyModel(nn.Module):
    """The network and its normalisers; ``stats`` holds the training set's min/max per input."""

    def __init__(self, cfg: DPConfig, stats: dict[str, tuple[torch.Tensor, torch.Tensor]]):
        super().__init__()
        self.cfg = cfg
        self.image_keys = image_keys(cfg)
        self.encoders = nn.ModuleDict({
            k: ImageEncoder(cfg.tactile_channels if k.startswith("tactile") else 3, cfg.encoder_widths,
                            cfg.encoder_blocks, cfg.image_feature_dim, resnet_stem=cfg.resnet_stem,
                            channels_last=cfg.precision == "bf16")  # fp32 stays the reference layout
            for k in self.image_keys})
        self.normalize = nn.ModuleDict({k: RangeNormalizer(*stats[k]) for k in self.low_dim_keys + ["action"]})
        per_frame = len(self.image_keys) * cfg.image_feature_dim + cfg.state_dim
        if cfg.tactile:
            per_frame += cfg.marker_motion_dim // cfg.obs_horizon
        self.global_cond_dim = per_frame * cfg.obs_horizon
        self.unet = ConditionalUnet1D(cfg.action_dim, self.global_cond_dim, cfg.unet_dims, cfg.unet_kernel,
                                      cfg.unet_groups, cfg.timestep_embed_dim)

    def use_channels_last(self, on: bool) -> None:
        """The image encoders' layout: NHWC (the bf16 default) or NCHW (fp32's, and float32 products')."""
        for encoder in self.encoders.values():
            encoder.use_channels_last(on)

    def mixed_precision(self):
        """The autocast context of the config's precision (a no-op for fp32)."""
        if self.cfg.precision != "bf16":
            return contextlib.nullcontext()
        return torch.autocast(device_type=self.normalize["action"].scale.device.type, dtype=torch.bfloat16)

    def weight_cast_cache(self):
        """A context in which autocast's bfloat16 copies of the weights outlive each network call.

        Autocast keeps those copies until the outermost autocast context exits, so a chunk of 16
        denoising steps cast every U-Net weight 16 times. This context is an autocast that is
        *disabled*: nothing inside it runs in another precision than before (only the
        ``mixed_precision`` blocks within do), but it holds the nesting level above zero, so the
        copies are made once per chunk. The copies are the same values, so a chunk is the same bit
        for bit (tests/test_baselines.py) and about a third cheaper in bf16 on the CPU
        (benchmarks/bench_train_step.py). Only for frozen weights: training changes them every step.
        """
        device = self.normalize["action"].scale.device.type
        if self.cfg.precision != "bf16" or torch.is_autocast_enabled(device):  # a caller's autocast keeps them already
            return contextlib.nullcontext()
        return torch.autocast(device_type=device, dtype=torch.bfloat16, enabled=False)

    def denoise(self, sample: torch.Tensor, step: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """The U-Net's noise prediction, float32 whatever the precision."""
        with self.mixed_precision():
            return self.unet(sample, step, cond).float()

    @property
    def low_dim_keys(self) -> list[str]:
        return ["state"] + (["markers"] if self.cfg.tactile else [])

    def encode(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """Observation windows (each (B, obs_horizon, ...); images uint8 HWC) -> (B, global_cond_dim)."""
        b, t = obs["state"].shape[:2]
        parts = []
        for k in self.image_keys:
            x = images_to_unit(obs[k]).flatten(0, 1)  # (B*T, C, H, W): the frames share the encoder
            with self.mixed_precision():
                features = self.encoders[k](x)
            parts.append(features.float().reshape(b, t, -1))
        for k in self.low_dim_keys:
            parts.append(self.normalize[k](obs[k].reshape(b, t, -1).float()))
        return torch.cat(parts, dim=-1).reshape(b, -1)

    def loss(self, obs: dict[str, torch.Tensor], actions: torch.Tensor, generator: torch.Generator,
             scheduler: DDPMScheduler) -> torch.Tensor:
        """Epsilon-prediction MSE on a batch of (B, action_horizon, 7) actions."""
        cond = self.encode(obs)
        target = self.normalize["action"](actions)
        # Drawn on the CPU generator, then moved: the same numbers on any device.
        noise = torch.randn(target.shape, generator=generator).to(target.device)
        steps = torch.randint(0, scheduler.config.num_train_timesteps, (target.shape[0],), generator=generator)
        noisy = scheduler.add_noise(target, noise, steps.to(target.device))
        steps = steps.to(target.device)
        return nn.functional.mse_loss(self.denoise(noisy, steps, cond), noise)

    @torch.no_grad()
    def sample(self, obs: dict[str, torch.Tensor], generator: torch.Generator, scheduler) -> torch.Tensor:
        """Denoise an action chunk from noise; returns (B, action_horizon, 7) in action units."""
        cond = self.encode(obs)
        x = torch.randn((cond.shape[0], self.cfg.action_horizon, self.cfg.action_dim), generator=generator)
        x = x.to(cond.device)
        scheduler.set_timesteps(self.cfg.inference_timesteps)
        with self.weight_cast_cache():
            for t in scheduler.timesteps:
                eps = self.denoise(x, t.expand(x.shape[0]).to(cond.device), cond)
                x = scheduler.step(eps, t, x, generator=generator).prev_sample
        return self.normalize["action"].inverse(x)


def empty_stats(cfg: DPConfig) -> dict:
    """Normaliser placeholders of the right shapes (a checkpoint's buffers overwrite them)."""
    z = lambda n: (torch.zeros(n), torch.ones(n))  # noqa: E731
    out = {"action": z(cfg.action_dim), "state": z(cfg.state_dim)}
    if cfg.tactile:
        out["markers"] = z(cfg.marker_motion_dim // cfg.obs_horizon)
    return out


def load_checkpoint(source: Path | bytes, name: str | Path | None = None) -> dict:
    """A checkpoint or policy file (a path, or its bytes already read, ``name`` naming it in errors)."""
    where = name or source
    try:
        return torch.load(io.BytesIO(source) if isinstance(source, bytes) else source, map_location="cpu",
                          weights_only=False)
    except Exception as e:  # noqa: BLE001 - torch raises many kinds for a damaged file
        raise ValueError(f"{where} cannot be read ({type(e).__name__}: {e}); it is damaged: delete it to "
                         "start over, or train into another --out") from None
