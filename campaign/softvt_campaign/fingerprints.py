"""The Diffusion Policy baselines' fingerprints, beside the library's (:mod:`mani_skill_softvt.fingerprints`
says how they are used; ``scripts/fingerprint.py`` runs both):

- ``dp_inference``: a committed Diffusion Policy's action chunk for a fixed observation window
  and noise seed (its bfloat16 encoders and U-Net, DDIM);
- ``dp_training``: a small Diffusion Policy config trained some steps on fixed synthetic windows:
  the weights, EMA and losses; ``dp_training_float32_products`` the same with the bfloat16 products
  through float32 kernels (:mod:`.baselines.bf16`, how a CPU without bfloat16 instructions trains).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mani_skill_softvt.fingerprints import sha


def _synthetic_window(cfg, model, rng: np.random.Generator, batch: int) -> dict:
    """Observation windows of ``batch`` samples with fixed pseudo-random content."""
    import torch

    t = cfg.obs_horizon
    obs = {"state": torch.from_numpy(rng.normal(size=(batch, t, cfg.state_dim)).astype(np.float32))}
    for k in model.image_keys:
        h, w = cfg.tactile_size if k.startswith("tactile") else cfg.camera_size
        c = cfg.tactile_channels if k.startswith("tactile") else 3
        obs[k] = torch.from_numpy(rng.integers(0, 256, (batch, t, h, w, c), dtype=np.uint8))
    if cfg.tactile:
        obs["markers"] = torch.from_numpy(rng.normal(size=(batch, t, 2, cfg.marker_count, 2)).astype(np.float32))
    return obs


def dp_inference(policy: str | Path = "campaign-data/policies/vt-c-cpu.pt") -> dict:
    """A committed policy's action chunk for a fixed observation window (one thread, as evaluated)."""
    chunk = _sample(policy)
    return {"chunk": chunk.numpy().round(6).tolist()[0][:2], "episode": sha(chunk)}


def _sample(policy: str | Path, context=None):
    """``policy``'s action chunk for the fixed window and noise seed, on one thread, inside ``context``."""
    import contextlib

    import torch

    from .baselines.agent import load_policy_file
    from .baselines.model import noise_scheduler

    cfg, model, _ = load_policy_file(Path(policy))
    model.eval()
    obs = _synthetic_window(cfg, model, np.random.default_rng(0), 1)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with context or contextlib.nullcontext():
            return model.sample(obs, torch.Generator().manual_seed(0), noise_scheduler(cfg, inference=True))
    finally:
        torch.set_num_threads(threads)


def dp_training(steps: int = 200, variant: str = "vt-c", bf16_products: str = "native") -> dict:
    """A small Diffusion Policy (the ``cpu`` preset's architecture, narrower; bfloat16 mixed
    precision, its products' kernels ``bf16_products``) trained ``steps`` steps of batch 8 on fixed
    synthetic windows, on one thread."""
    import torch

    from .baselines.config import make_config
    from .baselines.dataset import DemoWindows
    from .baselines.model import DiffusionPolicyModel, empty_stats
    from .baselines.train import Training

    cfg = make_config(variant, camera_size=(32, 32), tactile_size=(24, 32), encoder_widths=(8, 16),
                      encoder_blocks=(1, 1), image_feature_dim=16, unet_dims=(16, 32), timestep_embed_dim=16,
                      unet_groups=4, batch_size=8, steps=steps, warmup_steps=10, train_timesteps=50, threads=1)
    rng = np.random.default_rng(0)
    episodes, length = 4, 20
    probe = DiffusionPolicyModel(cfg, empty_stats(cfg))
    frames = {k: v[:, 0].numpy() for k, v in _synthetic_window(cfg, probe, rng, episodes * (length + 1)).items()}
    actions = rng.normal(size=(episodes * length, cfg.action_dim)).astype(np.float32)
    windows = DemoWindows(frames, actions, np.arange(episodes + 1) * (length + 1), np.arange(episodes + 1) * length, cfg)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        run = Training(cfg, windows.stats(), steps, bf16_products)
        for _ in range(steps):
            run.train_step(windows)
    finally:
        torch.set_num_threads(threads)
    weights = {"model": run.model.state_dict(), "ema": run.policy_state()}
    return {"last_loss": round(run.losses[-1], 6), "losses": sha(run.losses), "weights": sha(weights),
            "episode": sha([weights, run.losses])}


def dp_inference_trace(policy: str | Path = "campaign-data/policies/vt-c-cpu.pt") -> list[str]:
    """``dp_inference``'s computation call by call: ``"name:hash"`` for each torch function that
    returns tensors, in order (about 3,800 calls). Two traces made on different machines (an Intel and
    an AMD CPU, say) name the first call whose output differs (``scripts/fingerprint.py --trace-compare``):
    under the pins before 2026-12-06 that was a policy's bits between the two vendors (docs/install.md,
    numerics)."""
    import hashlib

    import torch
    from torch.overrides import TorchFunctionMode

    def digest(tensors) -> str:
        h = hashlib.sha256()
        for t in tensors:
            x = t.detach().clone()
            # numpy has no bfloat16: hash the 16-bit patterns
            x = x.view(torch.int16) if x.dtype in (torch.bfloat16, torch.float16) else x
            h.update(np.ascontiguousarray(x.numpy()).tobytes())
        return h.hexdigest()[:12]

    calls = []

    class Trace(TorchFunctionMode):  # torch's own hook on every function call (the mode is off inside it)
        def __torch_function__(self, func, types, args=(), kwargs=None):
            out = func(*args, **(kwargs or {}))
            tensors = [t for t in (out if isinstance(out, (tuple, list)) else [out]) if isinstance(t, torch.Tensor)]
            if tensors:
                calls.append(f"{torch.overrides.resolve_name(func) or getattr(func, '__name__', func)}:{digest(tensors)}")
            return out

    _sample(policy, Trace())
    return calls


def first_difference(a: list[str], b: list[str]) -> int | None:
    """The index of the first call where two traces differ (in name or output), None if they agree."""
    i = next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
    return None if i == len(a) == len(b) else i


def dp_training_float32_products() -> dict:
    """``dp_training`` with the bfloat16 products through float32 kernels."""
    return dp_training(bf16_products="float32")


CASES = {"dp_inference": dp_inference, "dp_training": dp_training,
         "dp_training_float32_products": dp_training_float32_products}
