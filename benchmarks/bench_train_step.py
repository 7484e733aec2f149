"""What a training step and a denoised chunk of the CPU Diffusion Policy baselines cost, by precision.

    .venv/bin/python benchmarks/bench_train_step.py [--steps 20] [--threads 1] [--variants vo-c vt-c] [--release-onednn]

For each variant (``cpu`` preset, batch 32, 84 px cameras) a full optimiser step of
``baselines.train.Training`` (random shift, encoders, U-Net loss, backward, AdamW, EMA) on a fixed
synthetic batch, and one denoised chunk as the agent samples it (batch 1, 16 DDIM steps), in three
settings: float32 with contiguous (NCHW) images, the reference and what the package trained with
before; float32 with channels-last images; the preset's bfloat16 autocast with channels-last and
the CPU's bfloat16 kernels (``native``); and the same autocast with its products through float32
kernels (``float32``, :mod:`softvt_campaign.baselines.bf16`: how ``softvt-train`` trains on a CPU
without bfloat16 instructions; its chunk is not timed, sampling always runs the native kernels).
``x fp32`` divides by the reference measured in this run, so machines compare. The process runs
pinned, as the package's import pins it; ``softvt-train`` releases oneDNN for a native bfloat16
run, and ``--release-onednn`` times every row so (on a CPU without bfloat16 instructions the two
are the same). In bf16 the chunk is
also timed as sampling ran before ``DiffusionPolicyModel.weight_cast_cache``, every U-Net call
casting the weights afresh (``chunk ms, cast per call``; the same actions bit for bit). The cost does not
depend on the weights or the pixel values, so untrained weights and random images are timed.
One thread is what each of the campaign's two parallel training runs gets.

A first table compares the two kinds of bfloat16 products with the arithmetic they stand for (the
bfloat16 operands' products summed exactly, rounded once): for a 3x3 convolution of the encoders'
width and a linear layer, forward and both gradients, the share of elements that are not that
correctly rounded value and the median relative error to the exact sum. One rounding gives about
2^-8 / 3 (1.3e-3) and a few elements off by a unit where float32's sum lands beside a rounding
boundary; a kernel that sums in bfloat16 or rounds twice shows more.

With ``--demos DIR`` a second table times the preset's step on real demo windows (``load_windows``
through ``--cache``: memory-mapped frames, the epoch's permutation, the gather) against the
synthetic batch, in alternating blocks of the same run so that the other jobs on the machine load
both alike: what the data path adds to a training step. ``--suite`` and ``--tasks`` pick the
demos (a few tasks are enough: the gather's cost per sample does not grow with the set).

    .venv/bin/python benchmarks/bench_train_step.py --variants vt-c --demos /root/softvt-demos \
        --suite object_rigid --tasks 0 --cache /tmp/bench-cache
"""

from __future__ import annotations

import argparse
import contextlib
import time
from pathlib import Path

import numpy as np
import torch

# (precision, channels-last images, bf16 products)
SETTINGS = (("fp32", False, None), ("fp32", True, None), ("bf16", True, "native"), ("bf16", False, "float32"))


class SyntheticWindows:
    """A stand-in for ``dataset.DemoWindows`` that returns one fixed random batch of the right shapes."""

    def __init__(self, cfg, model, seed: int = 0):
        rng = np.random.default_rng(seed)
        b, t = cfg.batch_size, cfg.obs_horizon
        obs = {"state": rng.uniform(-1, 1, (b, t, cfg.state_dim)).astype(np.float32)}
        for k in model.image_keys:
            h, w = cfg.tactile_size if k.startswith("tactile") else cfg.camera_size
            c = cfg.tactile_channels if k.startswith("tactile") else 3
            obs[k] = rng.integers(0, 256, (b, t, h, w, c), dtype=np.uint8)
        if cfg.tactile:
            obs["markers"] = rng.normal(0, 2, (b, t, 2, cfg.marker_count, 2)).astype(np.float32)
        self.obs = obs
        self.actions = rng.uniform(-1, 1, (b, cfg.action_horizon, cfg.action_dim)).astype(np.float32)

    def __len__(self) -> int:
        return 10_000

    def batch(self, indices):
        return {k: torch.from_numpy(v.copy()) for k, v in self.obs.items()}, torch.from_numpy(self.actions.copy())


def time_setting(variant: str, precision: str, channels_last: bool, products: str | None, steps: int,
                 chunks: int) -> tuple[float, float | None, float | None]:
    """(ms per training step, ms per denoised chunk (None for float32 products), the same with the
    weights cast per U-Net call (native bf16 only, else None)) of one setting."""
    from softvt_campaign.baselines.config import make_config
    from softvt_campaign.baselines.model import noise_scheduler
    from softvt_campaign.baselines.train import Training, empty_stats

    cfg = make_config(variant, "cpu", precision=precision, threads=0)
    run = Training(cfg, empty_stats(cfg), steps=steps + 3, bf16_products=products or "native")
    run.model.use_channels_last(channels_last)
    data = SyntheticWindows(cfg, run.model)
    for _ in range(3):  # warm-up: oneDNN picks its kernels on the first calls
        run.train_step(data)
    t0 = time.perf_counter()
    for _ in range(steps):
        run.train_step(data)
    step_ms = 1e3 * (time.perf_counter() - t0) / steps
    if products == "float32":
        return step_ms, None, None
    model = run.model.eval()
    obs = {k: v[:1] for k, v in data.batch(None)[0].items()}
    scheduler, generator = noise_scheduler(cfg, inference=True), torch.Generator().manual_seed(0)

    def chunk_ms() -> float:
        model.sample(obs, generator, scheduler)
        t0 = time.perf_counter()
        for _ in range(chunks):
            model.sample(obs, generator, scheduler)
        return 1e3 * (time.perf_counter() - t0) / chunks

    cached = chunk_ms()
    if precision != "bf16":
        return step_ms, cached, None
    model.weight_cast_cache = contextlib.nullcontext  # the instance's: sampling as it was before the cache
    return step_ms, cached, chunk_ms()


def accuracy_rows() -> list[str]:
    """The table of bfloat16 product kernels against their exact arithmetic (see the module's doc)."""
    from torch.nn import functional as F
    from torch.nn.grad import conv2d_input, conv2d_weight

    from softvt_campaign.baselines.bf16 import Float32Products

    g = torch.Generator().manual_seed(0)
    x = torch.randn(16, 64, 21, 21, generator=g).to(memory_format=torch.channels_last)
    w = 0.05 * torch.randn(64, 64, 3, 3, generator=g)
    dy = torch.randn(16, 64, 21, 21, generator=g).to(memory_format=torch.channels_last)
    z, lw, dh = torch.randn(64, 512, generator=g), 0.05 * torch.randn(256, 512, generator=g), torch.randn(64, 256, generator=g)
    bf = lambda t: t.to(torch.bfloat16).double()
    want = {"conv": F.conv2d(bf(x), bf(w), padding=1), "conv dx": conv2d_input(x.shape, bf(w), bf(dy), padding=1),
            "conv dw": conv2d_weight(bf(x), w.shape, bf(dy), padding=1), "linear": bf(z) @ bf(lw).T,
            "linear dz": bf(dh) @ bf(lw), "linear dw": bf(dh).T @ bf(z)}
    rows = ["bfloat16 products against their arithmetic (bf16 operands, exact sum, one rounding)", "",
            "| product | kernels | off the rounded value | median relative error |", "|---|---|---|---|"]
    for kind in ("native", "float32"):
        xs, ws, zs, lws = (t.to(torch.bfloat16).float().requires_grad_() for t in (x, w, z, lw))
        with Float32Products() if kind == "float32" else contextlib.nullcontext(), torch.autocast("cpu", torch.bfloat16):
            y, h = F.conv2d(xs, ws, padding=1), F.linear(zs, lws)
            y.backward(dy.to(torch.bfloat16))
            h.backward(dh.to(torch.bfloat16))
        got = {"conv": y, "conv dx": xs.grad, "conv dw": ws.grad, "linear": h, "linear dz": zs.grad, "linear dw": lws.grad}
        for name, exact_value in want.items():
            value = got[name].detach().double()
            off = float((value != exact_value.to(torch.bfloat16).double()).double().mean())
            rel = float(((value - exact_value).abs() / exact_value.abs().clamp_min(1e-12)).median())
            rows.append(f"| {name} | {kind} | {100 * off:.2f} % | {rel:.2e} |")
    return rows


def time_demo_windows(variant: str, demos, suite: str, tasks: list[int], cache, steps: int,
                      blocks: int = 5) -> dict:
    """Median ms per preset training step on the demo windows and on the synthetic batch, and per
    batch gather alone, over ``blocks`` alternating blocks of ``steps // blocks`` steps."""
    from softvt_campaign.baselines.config import make_config
    from softvt_campaign.baselines.dataset import load_windows
    from softvt_campaign.baselines.train import Training, batch_indices

    cfg = make_config(variant, "cpu", suite=suite, tasks=tuple(tasks), threads=0)
    windows = load_windows(cfg, demos, cache)
    run = Training(cfg, windows.stats(), steps=10 * steps + 6)
    synthetic = SyntheticWindows(cfg, run.model)
    for _ in range(3):  # warm-up, both inputs
        run.train_step(windows)
        run.train_step(synthetic)
    per_block = max(1, steps // blocks)
    times: dict[str, list[float]] = {"demo": [], "synthetic": [], "gather": []}
    for _ in range(blocks):
        for name, data in (("demo", windows), ("synthetic", synthetic)):
            t0 = time.perf_counter()
            for _ in range(per_block):
                run.train_step(data)
            times[name].append(1e3 * (time.perf_counter() - t0) / per_block)
        t0 = time.perf_counter()
        for k in range(per_block):
            windows.batch(batch_indices(cfg, len(windows), run.step + k))
        times["gather"].append(1e3 * (time.perf_counter() - t0) / per_block)
    return {"samples": len(windows), **{k: float(np.median(v)) for k, v in times.items()}}


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=20, help="timed optimiser steps per setting")
    ap.add_argument("--chunks", type=int, default=10, help="timed denoised chunks per setting")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--variants", nargs="+", default=["vo-c", "vt-c"])
    ap.add_argument("--release-onednn", action="store_true",
                    help="oneDNN's own CPU dispatch for every row, as softvt-train runs a native bfloat16 training")
    ap.add_argument("--demos", type=Path, default=None, help="also time the step on these rendered demos' windows")
    ap.add_argument("--suite", default="object_soft", help="with --demos: the suite whose demos are read")
    ap.add_argument("--tasks", type=int, nargs="+", default=[0], help="with --demos: the tasks read")
    ap.add_argument("--cache", type=Path, default=None,
                    help="with --demos (required): the prepared-data directory, memory-mapped as in training")
    args = ap.parse_args(argv)
    if args.demos is not None and args.cache is None:
        ap.error("--demos needs --cache DIR: training reads its windows memory-mapped from a data cache")
    if args.release_onednn:
        from mani_skill_softvt.provenance.numerics import release

        release("onednn")  # before torch's first oneDNN primitive, as softvt-train does
    torch.set_num_threads(args.threads)
    accuracy = accuracy_rows()
    print("\n".join(accuracy), flush=True)
    lines = accuracy + ["", f"training step (batch 32) and denoised chunk, cpu preset, {args.threads} thread(s), oneDNN "
             f"{'released' if args.release_onednn else 'pinned'}", "",
             "| variant | precision | bf16 products | images | step ms | x fp32 | steps/s | chunk ms | x fp32 | "
             "chunk ms, cast per call |", "|---|---|---|---|---|---|---|---|---|---|"]
    for variant in args.variants:
        ref = None
        for precision, cl, products in SETTINGS:
            step_ms, chunk_ms, per_call_ms = time_setting(variant, precision, cl, products, args.steps, args.chunks)
            ref = ref or (step_ms, chunk_ms)
            per_call = "-" if per_call_ms is None else f"{per_call_ms:.1f}"
            chunk = "- | -" if chunk_ms is None else f"{chunk_ms:.1f} | {chunk_ms / ref[1]:.2f}"
            lines.append(f"| {variant} | {precision} | {products or '-'} | {'channels-last' if cl else 'NCHW'} | "
                         f"{step_ms:.1f} | {step_ms / ref[0]:.2f} | {1e3 / step_ms:.2f} | {chunk} | {per_call} |")
            print(lines[-1], flush=True)
    if args.demos is not None:
        lines += ["", f"preset step on demo windows ({args.suite}, tasks {args.tasks}) against the synthetic batch, "
                      "alternating blocks", "",
                  "| variant | samples | synthetic ms | demo windows ms | x synthetic | gather ms |", "|---|---|---|---|---|---|"]
        for variant in args.variants:
            t = time_demo_windows(variant, args.demos, args.suite, args.tasks, args.cache, args.steps)
            lines.append(f"| {variant} | {t['samples']} | {t['synthetic']:.1f} | {t['demo']:.1f} | "
                         f"{t['demo'] / t['synthetic']:.2f} | {t['gather']:.1f} |")
            print(lines[-1], flush=True)
    table = "\n".join(lines)
    print()
    print(table)
    return table


if __name__ == "__main__":
    main()
