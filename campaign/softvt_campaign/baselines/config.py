"""One configuration object for the Diffusion Policy baselines, two presets, and overrides.

The paper's appendix "Baseline Training Details" fixes the recipe (``paper``): an image-
conditioned diffusion U-Net over a 16-step chunk of 7-D actions, 8 executed per replanning, two
observation frames; ResNet-18 image encoders, one per stream; AdamW (lr 1e-4, betas (0.95,
0.999), weight decay 1e-6), cosine schedule with 100 warm-up steps, EMA, DDPM with 100 steps for
training and inference, 20 epochs on 1,000 demonstrations per suite, batch 256 (VO) / 128 (VT) on
one A100. ``cpu`` keeps the architecture and the recipe but shrinks what costs time on a 2-core
machine: image size, encoder and U-Net widths, training steps, and the inference steps (DDIM over
the same 100-step noise schedule). Any field can be overridden (``--set key=value``).

Variants (paper, section "Baseline Training Details"):

======  ===========================================  =================
name    observation                                  gripper column
======  ===========================================  =================
vo-c    third-person + wrist RGB, robot state         continuous
vt-c    + both tactile images, 792-D marker motion    continuous
vo-b    as vo-c                                       binary
vt-b    as vt-c                                       binary
======  ===========================================  =================

Where this differs from the paper, and why:

- The tactile streams see the GelSight image *and* its depth map (``tactile_inputs="rgb+depth"``,
  the default). On objects softer than the gel the RGB change is faint (docs/tactile.md);
  ``tactile_inputs="rgb"`` gives the paper's input. The policy's name in a record says which.
- The paper's binary variants (VO-B, VT-B) are ablations of pi0.5, not of Diffusion Policy; here
  they are Diffusion Policy trained on the binary gripper column, as the benchmark's issue asks.
- The marker-motion input is the 792 numbers concatenated to the state, with no adapter network:
  the paper's VT Diffusion Policy has 455.7M trainable parameters against 433.2M here (VO: 329.2M
  in the paper, 329.3M here).
- Images are augmented by a random shift of ``shift_fraction`` of their size (edges replicated);
  Diffusion Policy random-crops about 10 %.
- ``paper`` is meant for a GPU (``device="cuda"``); it has not been run here.
- ``cpu`` trains and samples in bfloat16 mixed precision (``precision="bf16"``: the encoders'
  and the U-Net's matrix products under ``torch.autocast``, the image encoders on channels-last
  tensors (NCHW in a training whose products run on float32 kernels); weights, optimiser, normalisers, the spatial softmax and the loss stay float32). On
  this machine's AVX-512 BF16 cores a training step takes 0.61 of the float32 time
  (benchmarks/bench_train_step.py); on a CPU without bfloat16 instructions training computes the
  same products with float32 kernels (:mod:`.bf16`). ``precision="fp32"`` (NCHW images) is the
  reference, and what policy files from before the field was kept load as.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass

VARIANTS = ("vo-c", "vt-c", "vo-b", "vt-b")
PRESETS = ("paper", "cpu")
TACTILE_INPUTS = ("rgb", "rgb+depth")
SCHEDULERS = ("ddpm", "ddim")
PRECISIONS = ("fp32", "bf16")


@dataclass(frozen=True)
class DPConfig:
    """Everything that defines a Diffusion Policy baseline run (see the module docstring)."""

    variant: str = "vo-c"
    preset: str = "cpu"
    # -- interface (paper)
    obs_horizon: int = 2  # observation frames per prediction
    action_horizon: int = 16  # actions predicted per chunk
    action_steps: int = 8  # actions executed before replanning
    action_dim: int = 7  # base-frame xyz, axis-angle, gripper
    state_dim: int = 7  # base-frame TCP xyz, axis-angle, gripper width
    marker_count: int = 99
    # -- images
    camera_size: tuple[int, int] = (84, 84)  # (height, width) the two cameras are resized to
    tactile_size: tuple[int, int] = (60, 80)  # (height, width) of each tactile stream (4:3 like the sensor)
    tactile_inputs: str = "rgb+depth"
    depth_scale_um: float = 200.0  # the depth channel is indentation / this (tens of um on soft objects)
    # -- networks
    encoder_widths: tuple[int, ...] = (16, 32, 64, 128)  # ResNet stage widths (ResNet-18: 64..512)
    encoder_blocks: tuple[int, ...] = (1, 1, 1, 1)  # basic blocks per stage (ResNet-18: 2, 2, 2, 2)
    resnet_stem: bool = False  # ResNet-18's 7x7 stride-2 conv and max-pool; else one 3x3 stride-2 conv
    image_feature_dim: int = 64  # per image stream and frame
    unet_dims: tuple[int, ...] = (64, 128, 256)  # down-path channels of the 1-D U-Net
    unet_kernel: int = 5
    unet_groups: int = 8
    timestep_embed_dim: int = 64
    # -- diffusion
    train_timesteps: int = 100
    inference_timesteps: int = 16
    inference_scheduler: str = "ddim"
    # -- optimisation
    lr: float = 1e-4
    betas: tuple[float, float] = (0.95, 0.999)
    weight_decay: float = 1e-6
    warmup_steps: int = 100
    ema_power: float = 0.75  # EMA warm-up: decay = 1 - (1 + step)^-power, at most ema_max_decay (DP's values)
    ema_max_decay: float = 0.9999
    batch_size: int = 32
    shift_fraction: float = 0.05  # random-shift augmentation, a fraction of the image's shorter side
    epochs: float | None = None  # training length in epochs (paper), or
    steps: int | None = 3000  # in optimiser steps (cpu); exactly one of the two is set
    checkpoint_every: int = 250  # optimiser steps between checkpoints (resume point)
    seed: int = 0
    threads: int = 2  # torch intra-op threads while training (the machine's cores); 0: torch's default
    device: str = "cpu"  # where training runs ("cuda" for the paper preset)
    precision: str = "fp32"  # "bf16": mixed precision for the networks' products (the cpu preset's)
    # -- data
    suite: str = "object_soft"
    tasks: tuple[int, ...] = tuple(range(10))
    demos_per_task: int | None = None  # None: every accepted demo on disk (but the held-out ones)
    heldout_per_task: int = 0  # the last demos of each task, never trained on: the open-loop check's (openloop.py)

    def __post_init__(self):
        if self.variant not in VARIANTS:
            raise ValueError(f"variant {self.variant!r}: choose one of {VARIANTS}")
        if self.tactile_inputs not in TACTILE_INPUTS:
            raise ValueError(f"tactile_inputs {self.tactile_inputs!r}: choose one of {TACTILE_INPUTS}")
        if self.inference_scheduler not in SCHEDULERS:
            raise ValueError(f"inference_scheduler {self.inference_scheduler!r}: choose one of {SCHEDULERS}")
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision {self.precision!r}: choose one of {PRECISIONS}")
        if (self.epochs is None) == (self.steps is None):
            raise ValueError(f"set exactly one of epochs ({self.epochs}) and steps ({self.steps})")
        if not 1 <= self.action_steps <= self.action_horizon:
            raise ValueError(f"action_steps {self.action_steps} must be within 1..action_horizon {self.action_horizon}")
        if len(self.encoder_widths) != len(self.encoder_blocks):
            raise ValueError("encoder_widths and encoder_blocks need one entry per ResNet stage")
        if self.heldout_per_task < 0:
            raise ValueError(f"heldout_per_task {self.heldout_per_task} must be >= 0")
        if self.inference_timesteps > self.train_timesteps:
            raise ValueError(f"inference_timesteps {self.inference_timesteps} > train_timesteps {self.train_timesteps}")

    @property
    def tactile(self) -> bool:
        """Visuo-tactile variant (tactile images and marker motion as inputs)."""
        return self.variant.startswith("vt")

    @property
    def binary_gripper(self) -> bool:
        """Trained on the binary gripper column of the demonstrations (and its output thresholded)."""
        return self.variant.endswith("-b")

    @property
    def tactile_channels(self) -> int:
        return 4 if self.tactile_inputs == "rgb+depth" else 3

    @property
    def marker_motion_dim(self) -> int:
        """obs_horizon frames x 2 fingers x markers x 2 (the paper's 792 numbers)."""
        return self.obs_horizon * 2 * self.marker_count * 2

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


# The recipe search's recipes (studies/recipe_search.py, train --recipe): each varies one thing of the
# cpu preset (3,000 steps of batch 32 in bf16, 84 px cameras, ResNet widths 16-128, U-Net
# 64-256, 5 % shift, two observation frames, 8 of 16 actions executed).
RECIPES: dict[str, dict] = {
    "base": {},
    "long": {"steps": 12000},
    "wide": {"steps": 12000, "encoder_widths": (32, 64, 128, 256), "unet_dims": (128, 256, 512)},
    "img64": {"steps": 12000, "camera_size": (64, 64)},
    "noaug": {"steps": 12000, "shift_fraction": 0.0},
    "obs1": {"steps": 12000, "obs_horizon": 1},
    "exec4": {"steps": 12000, "action_steps": 4},
}

# Fields that change how a trained network is sampled, not how it trains: runs that differ only in
# these learn the same weights, bit for bit (the recipe search trains one and derives the others).
INFERENCE_FIELDS = ("action_steps", "inference_timesteps", "inference_scheduler")


def training_identity(cfg: DPConfig) -> str:
    """The config without its inference fields, as text: equal for runs that train alike."""
    return json.dumps({k: v for k, v in cfg.to_dict().items() if k not in INFERENCE_FIELDS}, sort_keys=True, default=list)


def recipe_config(variant: str, recipe: str = "base", overrides: dict | None = None, **extra) -> DPConfig:
    """The cpu preset of ``variant`` with the named recipe's overrides (:data:`RECIPES`), then
    ``overrides`` (``--set``), then ``extra``."""
    if recipe not in RECIPES:
        raise ValueError(f"recipe {recipe!r}: choose one of {sorted(RECIPES)}")
    return make_config(variant, "cpu", **{**RECIPES[recipe], **(overrides or {}), **extra})


# The appendix's settings (a GPU run; documented, not run here).
_PAPER = dict(preset="paper", camera_size=(224, 224), tactile_size=(240, 320), encoder_widths=(64, 128, 256, 512),
              encoder_blocks=(2, 2, 2, 2), resnet_stem=True, image_feature_dim=512, unet_dims=(512, 1024, 2048), timestep_embed_dim=128,
              train_timesteps=100, inference_timesteps=100, inference_scheduler="ddpm", batch_size=256, epochs=20.0,
              steps=None, checkpoint_every=1000, threads=0, device="cuda", demos_per_task=100)
_CPU: dict = dict(preset="cpu", precision="bf16")


def make_config(variant: str, preset: str = "cpu", **overrides) -> DPConfig:
    """The ``preset`` configuration of ``variant`` with ``overrides`` applied (field names)."""
    if preset not in PRESETS:
        raise ValueError(f"preset {preset!r}: choose one of {PRESETS}")
    base = dict(_PAPER if preset == "paper" else _CPU)
    if preset == "paper" and variant.startswith("vt"):
        base["batch_size"] = 128  # the appendix's VT micro-batch (no accumulation)
    unknown = sorted(set(overrides) - {f.name for f in dataclasses.fields(DPConfig)})
    if unknown:
        raise ValueError(f"unknown config fields {unknown}; the fields are those of DPConfig")
    if "epochs" in overrides and "steps" not in overrides:
        base["steps"] = None  # training length given in epochs replaces the preset's step count
    if "steps" in overrides and "epochs" not in overrides:
        base["epochs"] = None
    return DPConfig(variant=variant, **{**base, **overrides})


def parse_override(text: str) -> tuple[str, object]:
    """``key=value`` from the command line, the value typed like the field's default
    (tuples as comma lists, ``none`` for None)."""
    if "=" not in text:
        raise ValueError(f"override {text!r} is not key=value")
    key, raw = text.split("=", 1)
    fields = {f.name: f for f in dataclasses.fields(DPConfig)}
    if key not in fields:
        raise ValueError(f"override {text!r}: no config field {key!r}; fields: {sorted(fields)}")
    default = getattr(DPConfig(), key)
    if raw.lower() == "none":
        return key, None
    try:
        if isinstance(default, tuple):
            kind = type(default[0]) if default else int
            return key, tuple(kind(v) for v in raw.split(",") if v)
        if isinstance(default, bool):
            return key, raw.lower() in ("1", "true", "yes")
        if key in ("epochs",):
            return key, float(raw)
        if key in ("steps", "demos_per_task", "heldout_per_task"):
            return key, int(raw)
        return key, type(default)(raw) if default is not None else raw
    except ValueError as e:
        raise ValueError(f"override {text!r}: {e}") from e
