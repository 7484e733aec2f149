"""Train a Diffusion Policy baseline on rendered expert demonstrations (resumable).

    python -m softvt_campaign.baselines.train --variant vt-c                    # cpu preset, Object-Soft
    python -m softvt_campaign.baselines.train --variant vo-c --config paper     # the appendix's recipe (GPU)
    python -m softvt_campaign.baselines.train --variant vo-b --set steps=500 batch_size=16
    python -m softvt_campaign.baselines.train --variant vo-c --recipe long --budget-min 150 --cache /data/cache

Needs the suite's demos generated and rendered with ``--obs-mode rgb+tactile`` (docs/baselines.md).
``--recipe`` applies one of the named recipes (:data:`~.config.RECIPES`) before ``--set``;
``--budget-min`` stops at the first checkpoint after that many minutes (run the same command again
to continue). Writes under ``--out`` (default ``outputs/baselines/<suite>/<variant>-<config>[-<recipe>]``):

- ``checkpoint.pt``: everything to resume (weights, EMA, optimiser, schedule, random state,
  losses), rewritten atomically every ``checkpoint_every`` steps; re-running the same command
  continues from it, and the result is bit for bit the one an uninterrupted run gives (on a
  machine of the same kind, with the same ``--bf16-products``: a run resumed with the other kind
  trains each stretch its own way, and ``bf16_product_steps`` counts them);
- ``policy.pt``: the EMA weights and the config, what ``evaluate --policy <path>`` loads;
- with ``--snapshot-every N``, ``snapshots/<run>_step<k>.pt``: the same at every N-th step (a
  policy each, for curves of error or TSR against training time);
- ``loss.png``: the training loss; ``data_cache/``: the prepared demonstrations (:mod:`.dataset`),
  unless ``--cache`` names a directory shared between runs.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import time
from pathlib import Path

import numpy as np
import torch
from diffusers.optimization import get_cosine_schedule_with_warmup
from diffusers.training_utils import EMAModel
from matplotlib.figure import Figure
from tqdm import tqdm

from mani_skill_softvt.fileio import atomic_write
from mani_skill_softvt.provenance.numerics import chosen as chosen_numerics
from mani_skill_softvt.provenance.numerics import release, resolved
from mani_skill_softvt.paths import DEMOS_DIR, REPO_DIR
from mani_skill_softvt.tasks.suites import get_suite
from .bf16 import BF16_PRODUCTS, Float32Products, choose_products
from .config import (
    PRESETS,
    RECIPES,
    VARIANTS,
    DPConfig,
    make_config,
    parse_override,
    recipe_config,
)
from .dataset import DemoWindows, data_key, load_windows
from .model import DiffusionPolicyModel, empty_stats, load_checkpoint, noise_scheduler  # noqa: F401  (re-exported)

CHECKPOINT, POLICY, CACHE = "checkpoint.pt", "policy.pt", "data_cache"


def default_out(cfg: DPConfig, recipe: str | None = None) -> Path:
    name = f"{cfg.variant}-{cfg.preset}" + (f"-{recipe}" if recipe and recipe != "base" else "")
    return REPO_DIR / "outputs" / "baselines" / cfg.suite / name


def random_shift(images: torch.Tensor, pad: int, generator: torch.Generator) -> torch.Tensor:
    """Shift each sample's frames (B, T, H, W, C) by one random offset within +-``pad`` px, edges
    replicated: the augmentation that keeps a small image encoder from memorising pixels."""
    b, t, h, w, c = images.shape
    x = images.permute(0, 1, 4, 2, 3).reshape(b, t * c, h, w).float()
    x = torch.nn.functional.pad(x, (pad, pad, pad, pad), mode="replicate")
    dy, dx = torch.randint(0, 2 * pad + 1, (2, b), generator=generator)
    out = torch.stack([x[i, :, dy[i]:dy[i] + h, dx[i]:dx[i] + w] for i in range(b)])
    return out.reshape(b, t, c, h, w).permute(0, 1, 3, 4, 2).to(images.dtype)


def steps_per_epoch(cfg: DPConfig, samples: int) -> int:
    """Full batches per pass over the samples (the last ``samples % batch_size`` wait for the next
    epoch's permutation)."""
    return max(1, samples // cfg.batch_size)


def total_steps(cfg: DPConfig, samples: int) -> int:
    if cfg.steps is not None:
        return cfg.steps
    return math.ceil(cfg.epochs * steps_per_epoch(cfg, samples))


def batch_indices(cfg: DPConfig, samples: int, step: int) -> np.ndarray:
    """The samples of optimiser step ``step``: a fresh permutation per epoch, seeded by (seed, epoch),
    so that a resumed run draws the batches an uninterrupted one would."""
    per_epoch = steps_per_epoch(cfg, samples)
    epoch, k = divmod(step, per_epoch)
    perm = np.random.default_rng([cfg.seed, epoch]).permutation(samples)
    if samples < cfg.batch_size:
        return perm
    return perm[k * cfg.batch_size:(k + 1) * cfg.batch_size]


class Training:
    """Model, EMA, optimiser and schedule of one run, with save and load."""

    def __init__(self, cfg: DPConfig, stats: dict, steps: int, bf16_products: str = "native"):
        """``bf16_products``: in a bf16 run, the kernels of its products, ``"native"`` or
        ``"float32"`` (:mod:`.bf16`); a float32 run ignores it."""
        if cfg.precision == "bf16" and bf16_products not in ("native", "float32"):
            raise ValueError(f"bf16_products {bf16_products!r}: native or float32 (see baselines/bf16.py)")
        torch.manual_seed(cfg.seed)  # weight initialisation
        self.bf16_products = bf16_products if cfg.precision == "bf16" else None
        # Steps trained with each kind of bfloat16 products: a run may resume on another machine.
        self.bf16_product_steps: dict[str, int] = {}
        self.cfg, self.steps, self.device = cfg, steps, torch.device(cfg.device)
        self.model = DiffusionPolicyModel(cfg, stats).to(self.device)
        if self.bf16_products == "float32":
            self.model.use_channels_last(False)  # float32 kernels on NCHW: no layout copies (baselines/bf16.py)
        self.ema = EMAModel(self.model.parameters(), decay=cfg.ema_max_decay, use_ema_warmup=True, inv_gamma=1.0,
                            power=cfg.ema_power)
        self.optimizer = torch.optim.AdamW(self.model.parameters(), lr=cfg.lr, betas=cfg.betas,
                                           weight_decay=cfg.weight_decay)
        self.lr_schedule = get_cosine_schedule_with_warmup(self.optimizer, cfg.warmup_steps, steps)
        self.noise = noise_scheduler(cfg)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.step = 0
        self.losses: list[float] = []
        self.wall_s = 0.0  # training time so far, over every call that resumed the run

    def state(self, data_key: str) -> dict:
        return {"config": self.cfg.to_dict(), "steps": self.steps, "data_key": data_key, "step": self.step, "model": self.model.state_dict(),
                "ema": self.ema.state_dict(), "optimizer": self.optimizer.state_dict(),
                "lr_schedule": self.lr_schedule.state_dict(), "generator": self.generator.get_state(),
                "losses": self.losses, "wall_s": self.wall_s, "bf16_product_steps": self.bf16_product_steps}

    def load(self, ckpt: dict) -> None:
        self.model.load_state_dict(ckpt["model"])
        self.ema.load_state_dict(ckpt["ema"])
        self.optimizer.load_state_dict(ckpt["optimizer"])
        self.lr_schedule.load_state_dict(ckpt["lr_schedule"])
        self.generator.set_state(ckpt["generator"])
        self.step, self.losses = int(ckpt["step"]), list(ckpt["losses"])
        self.wall_s = float(ckpt.get("wall_s", 0.0))
        # Checkpoints before the choice existed trained every bfloat16 step with the native kernels.
        default = {"native": self.step} if self.bf16_products and self.step else {}
        self.bf16_product_steps = dict(ckpt.get("bf16_product_steps", default))

    def train_step(self, windows: DemoWindows) -> float:
        obs, actions = windows.batch(batch_indices(self.cfg, len(windows), self.step))
        for k in self.model.image_keys:
            pad = max(1, round(self.cfg.shift_fraction * min(obs[k].shape[2:4])))
            obs[k] = random_shift(obs[k], pad, self.generator)
        obs = {k: v.to(self.device) for k, v in obs.items()}
        actions = actions.to(self.device)
        self.model.train()
        with Float32Products() if self.bf16_products == "float32" else contextlib.nullcontext():
            loss = self.model.loss(obs, actions, self.generator, self.noise)
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
        self.optimizer.step()
        self.lr_schedule.step()
        self.ema.step(self.model.parameters())
        self.step += 1
        if self.bf16_products:
            self.bf16_product_steps[self.bf16_products] = self.bf16_product_steps.get(self.bf16_products, 0) + 1
        self.losses.append(float(loss.detach()))
        return self.losses[-1]

    def policy_state(self) -> dict:
        """The EMA weights as a model state dict (what evaluation loads)."""
        model = DiffusionPolicyModel(self.cfg, empty_stats(self.cfg)).to(self.device)
        model.load_state_dict(self.model.state_dict())
        self.ema.copy_to(model.parameters())
        return {k: v.cpu() for k, v in model.state_dict().items()}

    def policy_file(self, windows: DemoWindows) -> dict:
        """What a ``policy.pt`` (or a snapshot) holds: the config, the EMA weights at this step and
        what they were trained on."""
        return {"config": self.cfg.to_dict(), "model": self.policy_state(), "steps": self.step,
                "tactile_model": get_suite(self.cfg.suite).tactile_model if self.cfg.tactile else None,
                "episodes": windows.episodes, "samples": len(windows),
                "camera_render_size": list(windows.camera_render_size), "train_wall_s": self.wall_s,
                "data_key": windows.key, "data_cache": None if windows.cache is None else str(windows.cache.resolve()),
                "numerics": resolved(), "bf16_product_steps": self.bf16_product_steps}


def save(path: Path, obj: dict) -> None:
    def write(tmp: Path):
        with tmp.open("wb") as fh:
            torch.save(obj, fh)

    atomic_write(path, write)


def check_same_run(ckpt: dict, cfg: DPConfig, path: Path, data_key: str | None = None, steps: int | None = None) -> None:
    """Refuse to resume ``ckpt`` with another configuration, other demonstrations (regenerated or
    re-rendered: other normalisers and batches) or another length (another schedule)."""
    if "precision" not in ckpt.get("config", {}):
        raise ValueError(f"{path} was written by an older version of this package (before the precision field; it "
                         "trained in float32 throughout): train into another --out, or delete it to start over")
    if ckpt.get("config") != cfg.to_dict():
        diff = sorted(k for k in cfg.to_dict() if ckpt.get("config", {}).get(k) != cfg.to_dict()[k])
        raise ValueError(f"{path} is a run with another configuration (differs in {diff}); train into another "
                         "--out, or repeat that run's --config/--set to resume it")
    if data_key is not None and ckpt.get("data_key") != data_key:
        raise ValueError(f"{path} was trained on other demonstration files (generated or rendered again since); "
                         "train into another --out, or delete it to start over on these")
    if steps is not None and ckpt.get("steps") != steps:
        raise ValueError(f"{path} plans {ckpt.get('steps')} steps, this run {steps} (another number of demos); "
                         "train into another --out")


def plot_losses(losses: list[float], path: Path, title: str) -> None:
    fig = Figure(figsize=(6, 3.5))
    ax = fig.subplots()
    steps = np.arange(1, len(losses) + 1)
    ax.semilogy(steps, losses, lw=0.5, alpha=0.4, label="batch")
    if len(losses) >= 50:
        k = 50
        ax.semilogy(steps[k - 1:], np.convolve(losses, np.ones(k) / k, mode="valid"), lw=1.5, label=f"mean of {k}")
    ax.set_xlabel("optimiser step")
    ax.set_ylabel("noise-prediction MSE")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=120))


def snapshot_path(out: Path, step: int) -> Path:
    """Where the snapshot policy of step ``step`` of the run in ``out`` goes (named after the run,
    so that its evaluation records are too)."""
    return Path(out) / "snapshots" / f"{Path(out).name}_step{step:06d}.pt"


def train(cfg: DPConfig, demos_root: Path, out: Path, stop_after: int | None = None, progress: bool = True,
          deadline: float | None = None, snapshot_every: int | None = None, cache: Path | None = None,
          bf16_products: str = "native") -> Path:
    """Train (or resume) the run in ``out``; returns the path of ``policy.pt``. ``stop_after``
    ends this call after that many optimiser steps, ``deadline`` (``time.monotonic()``) at the
    first checkpoint after it (the run resumes later, the same as an uninterrupted one).
    ``snapshot_every`` keeps a snapshot policy every that many steps (:func:`snapshot_path`).
    ``cache``: the prepared-data directory (default ``out/data_cache``; runs may share one).
    ``bf16_products``: ``"native"`` or ``"float32"``, the kernels of a bf16 run's products (:mod:`.bf16`)."""
    if cfg.threads > 0:
        torch.set_num_threads(cfg.threads)
    out = Path(out)
    ckpt_path, policy_path = out / CHECKPOINT, out / POLICY
    ckpt = load_checkpoint(ckpt_path) if ckpt_path.exists() else None
    if ckpt is not None:
        # Everything that can be refused is refused before minutes of preparing data.
        check_same_run(ckpt, cfg, ckpt_path, data_key(cfg, demos_root))
        if ckpt["step"] == ckpt["steps"] and policy_path.exists():
            return policy_path  # finished: nothing to do, and policy.pt is not written again
    if (out / "data_cache.npz").exists():
        print(f"note: {out / 'data_cache.npz'} is an older version's data cache, no longer read; delete it "
              f"({(out / 'data_cache.npz').stat().st_size / 2 ** 30:.1f} GB)")
    windows = load_windows(cfg, demos_root, out / CACHE if cache is None else cache)
    steps = total_steps(cfg, len(windows))
    if ckpt is not None:
        check_same_run(ckpt, cfg, ckpt_path, windows.key, steps)
    run = Training(cfg, windows.stats(), steps, bf16_products)
    if ckpt is not None:
        run.load(ckpt)
    end = steps if stop_after is None else min(steps, run.step + stop_after)
    with tqdm(total=steps, initial=run.step, desc=f"train {cfg.variant}", unit="step", disable=not progress) as bar:
        while run.step < end:
            t0 = time.perf_counter()
            loss = run.train_step(windows)
            run.wall_s += time.perf_counter() - t0
            bar.update()
            bar.set_postfix(loss=f"{loss:.4f}")
            if snapshot_every and run.step % snapshot_every == 0:
                save(snapshot_path(out, run.step), run.policy_file(windows))
            if run.step % cfg.checkpoint_every == 0 or run.step == end:
                save(ckpt_path, run.state(windows.key))
                if deadline is not None and time.monotonic() >= deadline:
                    break
    if run.step == steps:
        save(policy_path, run.policy_file(windows))
        plot_losses(run.losses, out / "loss.png", f"{cfg.variant} ({cfg.preset}), {windows.episodes} demos")
    return policy_path


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variant", required=True, choices=VARIANTS)
    ap.add_argument("--config", default="cpu", choices=PRESETS, help="the appendix's recipe (paper) or the 2-core one")
    ap.add_argument("--recipe", default=None, choices=sorted(RECIPES), help="a named recipe of the search (config.RECIPES)")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="override config fields (DPConfig)")
    ap.add_argument("--demos", type=Path, default=DEMOS_DIR, help="demos root (generate + render output)")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--cache", type=Path, default=None, help="prepared-data directory (default: OUT/data_cache)")
    ap.add_argument("--budget-min", type=float, default=None,
                    help="stop at the first checkpoint after this many minutes (run again to continue)")
    ap.add_argument("--snapshot-every", type=int, default=None, metavar="N",
                    help="also keep the policy of every N-th step (snapshots/), for curves against training time")
    ap.add_argument("--bf16-products", default="auto", choices=BF16_PRODUCTS,
                    help="a bf16 run's convolutions and matrix products: the CPU's bfloat16 kernels (native) or "
                         "float32 kernels on the same operands, rounded once (float32: the same arithmetic, 11-14x "
                         "cheaper a step on a CPU without bfloat16 instructions); auto: native where the CPU has them")
    args = ap.parse_args(argv)
    try:
        if args.recipe and args.config != "cpu":
            raise ValueError(f"--recipe {args.recipe} varies the cpu preset; with --config {args.config} use --set")
        overrides = dict(parse_override(s) for s in args.set)
        cfg = (recipe_config(args.variant, args.recipe, overrides) if args.recipe else
               make_config(args.variant, args.config, **overrides))
    except ValueError as e:
        ap.error(str(e))
    out = args.out or default_out(cfg, args.recipe)
    deadline = None if args.budget_min is None else time.monotonic() + 60 * args.budget_min
    products = choose_products(args.bf16_products, cfg.precision)
    if products == "native" and "onednn" in chosen_numerics().parts:
        # Pinned to AVX2, oneDNN emulates bfloat16 and a step costs 23x (docs/benchmarks.md): the training
        # takes the CPU's own bfloat16 kernels, and its weights reproduce on machines of this kind.
        release("onednn")
        print("note: bfloat16 training runs oneDNN's own CPU dispatch (the pinned AVX2 one costs 23x a step); "
              "the weights reproduce on machines of this kind, the evaluations of the policy on any")
    elif products == "float32":
        # No bfloat16 kernel runs, so every dispatch stays pinned.
        why = "asked for" if args.bf16_products == "float32" else "this CPU has no bfloat16 instructions"
        print(f"note: bfloat16 products through float32 kernels ({why}; baselines/bf16.py), nothing released")
    path = train(cfg, args.demos, out, snapshot_every=args.snapshot_every, deadline=deadline, cache=args.cache,
                 bf16_products=products or "native")
    print(f"{path}" if path.exists() else f"stopped before the end; re-run to resume from {out / CHECKPOINT}")
    return path


if __name__ == "__main__":
    main()
