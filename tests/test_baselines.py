"""Diffusion Policy baselines: inputs, windows, training (determinism, resume), the evaluation agent.

Synthetic demonstration files in the package's on-disk layout keep these fast; the networks are
shrunk with config overrides. The real training and evaluation runs are in docs/baselines.md.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from softvt_campaign.baselines import train as T
from softvt_campaign.baselines.agent import DiffusionPolicyAgent, load_policy_file
from softvt_campaign.baselines.config import make_config, parse_override
from softvt_campaign.baselines.dataset import load_windows
from softvt_campaign.baselines.features import robot_state, tactile_image
from mani_skill_softvt.data.demo_set import DemoSet
from mani_skill_softvt.evaluation.policies import load_policy
from mani_skill_softvt.physics.transforms import down_quat, down_rotvec
from mani_skill_softvt.tasks import constants as C
from mani_skill_softvt.tasks.suites import SUITES

TACTILE_MODEL_VERSION = SUITES["object_soft"].tactile_model  # the demos here are Object-Soft's

TINY = dict(camera_size=(16, 16), tactile_size=(12, 16), encoder_widths=(4, 8), encoder_blocks=(1, 1),
            image_feature_dim=8, unet_dims=(8, 16), timestep_embed_dim=8, unet_groups=4, batch_size=4, steps=6,
            checkpoint_every=2, warmup_steps=2, tasks=(0,), threads=1, train_timesteps=20, inference_timesteps=4)


def _write_demos(root, lengths=(9, 6), seed=0, tactile_model=TACTILE_MODEL_VERSION, camera_size=(224, 224),
                 suite="object_soft", twin_contact=False):
    """Task 0 of ``suite``: a trajectory file and its rgb+tactile rendering with the cameras at
    ``camera_size`` (random images, an action that moves with the state so that there is
    something to learn). Called again with another size, it adds that rendering. ``twin_contact``:
    the states hold the twins' contact wrenches (a rigid recording since they are kept)."""
    rng = np.random.default_rng(seed)
    ds = DemoSet(root, suite)
    ds.dir.mkdir(parents=True, exist_ok=True)
    with h5py.File(ds.trajectory(0), "w") as ft, h5py.File(ds.rendered(0, "rgb+tactile", camera_size), "w") as fr:
        for e, t in enumerate(lengths):
            a = np.zeros((t, 7), np.float32)
            a[:, 0] = np.linspace(0.5, 0.6, t)
            a[:, 3:6] = down_rotvec(0.1)
            a[:, 6] = np.linspace(0, 0.8, t)
            g = ft.create_group(f"traj_{e}")
            g["actions"], g["actions_binary"] = a, np.where(np.arange(7) == 6, (a > 0.4), a).astype(np.float32)
            if twin_contact:
                g["env_states/contact_wrenches"] = np.zeros((t + 1, 18))
            o = fr.create_group(f"traj_{e}/obs")
            fr[f"traj_{e}"].attrs["states_sha256"] = f"episode {e} of seed {seed}"  # as demos render keeps it
            if tactile_model is not None:
                fr[f"traj_{e}"].attrs["tactile_model"] = tactile_model
            pose = np.tile(np.r_[0.0, 0.0, 0.2, down_quat(0.1)], (t + 1, 1)).astype(np.float32)
            pose[:, 0] = np.r_[a[:, 0], a[-1, 0]] + C.ROBOT_BASE_POSE[0]
            o["extra/tcp_pose"], o["extra/gripper_width"] = pose, np.full((t + 1, 1), 0.08, np.float32)
            o["agent/qpos"] = np.tile(np.r_[np.zeros(7), 0.04, 0.04], (t + 1, 1)).astype(np.float32)
            for cam in ("base_camera", "hand_camera"):
                o[f"sensor_data/{cam}/rgb"] = rng.integers(0, 256, (t + 1, *camera_size, 3), dtype=np.uint8)
            for s in ("left", "right"):
                o[f"tactile/{s}/rgb"] = rng.integers(0, 256, (t + 1, 240, 320, 3), dtype=np.uint8)
                o[f"tactile/{s}/depth"] = rng.integers(0, 100, (t + 1, 240, 320), dtype=np.int16)
                o[f"tactile/{s}/marker_initial"] = np.zeros((t + 1, 99, 2), np.float32)
                o[f"tactile/{s}/marker_current"] = rng.normal(size=(t + 1, 99, 2)).astype(np.float32)
    return ds


# ------------------------------------------------------------------------------------ inputs

def test_robot_state_is_continuous_through_the_half_turn():
    # The top-down hand is a half turn: quat_to_rotvec's two branches differ by 2 pi in length.
    # The state must take the branch of the actions (down_rotvec) for yaw on both sides of 0,
    # and the sign of the quaternion must not matter.
    for yaw in (-0.3, -1e-4, 0.0, 1e-4, 0.3):
        for sign in (1.0, -1.0):
            s = robot_state(np.r_[0.1, 0.2, 0.3, sign * down_quat(yaw)], 0.05)
            np.testing.assert_allclose(s[3:6], down_rotvec(yaw), atol=1e-6)
            np.testing.assert_allclose(s[:3], np.r_[0.1, 0.2, 0.3] - C.ROBOT_BASE_POSE[:3], atol=1e-7)
            assert s[6] == np.float32(0.05)


def test_tactile_stream_scales_depth_to_the_configured_range():
    cfg = make_config("vt-c", tactile_size=(60, 80))
    rgb = np.full((240, 320, 3), 100, np.uint8)
    depth = np.zeros((240, 320), np.int16)
    depth[:120] = 100  # 100 um over the top half: half of depth_scale_um = 200 um
    img = tactile_image(rgb, depth, cfg)
    assert img.shape == (60, 80, 4) and img.dtype == np.uint8
    assert (img[..., :3] == 100).all()
    np.testing.assert_array_equal(img[:30, :, 3], 128)  # round(100 * 255 / 200)
    np.testing.assert_array_equal(img[30:, :, 3], 0)
    with pytest.raises(ValueError, match="depth"):
        tactile_image(rgb, None, cfg)
    assert tactile_image(rgb, None, make_config("vt-c", tactile_inputs="rgb")).shape[-1] == 3


def test_config_presets_and_overrides():
    paper = make_config("vt-b", "paper")
    assert (paper.lr, paper.betas, paper.weight_decay, paper.warmup_steps) == (1e-4, (0.95, 0.999), 1e-6, 100)
    assert (paper.train_timesteps, paper.inference_timesteps, paper.inference_scheduler) == (100, 100, "ddpm")
    assert (paper.action_horizon, paper.action_steps, paper.obs_horizon, paper.epochs) == (16, 8, 2, 20.0)
    assert paper.batch_size == 128 and make_config("vo-b", "paper").batch_size == 256
    assert paper.binary_gripper and paper.tactile and paper.marker_motion_dim == 792
    assert make_config("vo-c", steps=5).steps == 5
    assert make_config("vo-c", "paper", steps=5).epochs is None
    assert parse_override("camera_size=96,96") == ("camera_size", (96, 96))
    assert parse_override("epochs=2") == ("epochs", 2.0)
    with pytest.raises(ValueError, match="no config field"):
        parse_override("learning_rate=1")
    with pytest.raises(ValueError, match="variant"):
        make_config("vt-x")
    assert (make_config("vo-c").precision, paper.precision) == ("bf16", "fp32")
    with pytest.raises(ValueError, match="precision"):
        make_config("vo-c", precision="fp16")


def random_window(cfg, image_keys, batch: int, g: torch.Generator) -> dict:
    """A random vt observation window of ``batch`` (obs_horizon 2): state, markers, uint8 images."""
    obs = {"state": torch.rand(batch, 2, 7, generator=g), "markers": torch.randn(batch, 2, 2, 99, 2, generator=g)}
    for k in image_keys:
        h, w = cfg.tactile_size if k.startswith("tactile") else cfg.camera_size
        obs[k] = torch.randint(0, 256, (batch, 2, h, w, cfg.tactile_channels if k.startswith("tactile") else 3),
                               generator=g, dtype=torch.uint8)
    return obs


def test_bf16_mixed_precision_stays_within_bfloat16_rounding_of_float32():
    # bfloat16 keeps 8 significant bits: each product is rounded by at most 2^-9 relative, and the
    # errors of a few dozen layers add up at random (sqrt(n) 2^-9, ~2 %). The same weights in
    # float32 and bf16 give features and noise predictions that close, in float32; channels-last
    # is only another memory layout (float32 summation-order differences, ~1e-6).
    from softvt_campaign.baselines.model import DiffusionPolicyModel
    from softvt_campaign.baselines.networks import ImageEncoder

    cfg32 = make_config("vt-c", **{**TINY, "precision": "fp32"})
    cfg16 = make_config("vt-c", **{**TINY, "precision": "bf16"})
    torch.manual_seed(0)
    m32 = DiffusionPolicyModel(cfg32, T.empty_stats(cfg32))
    m16 = DiffusionPolicyModel(cfg16, T.empty_stats(cfg16))
    m16.load_state_dict(m32.state_dict())
    g = torch.Generator().manual_seed(1)
    obs = random_window(cfg32, m32.image_keys, 3, g)
    with torch.no_grad():
        c32, c16 = m32.encode(obs), m16.encode(obs)
        x, t = torch.randn(3, 16, 7, generator=g), torch.tensor([0, 7, 19])
        e32, e16 = m32.denoise(x, t, c32), m16.denoise(x, t, c32)
    assert c16.dtype == e16.dtype == torch.float32
    rel = lambda a, b: float((a - b).norm() / b.norm())
    assert 0 < rel(c16, c32) < 0.03 and 0 < rel(e16, e32) < 0.03
    nchw = ImageEncoder(3, (4, 8), (1, 1), 8)
    nhwc = ImageEncoder(3, (4, 8), (1, 1), 8, channels_last=True)
    nhwc.load_state_dict(nchw.state_dict())
    img = torch.rand(2, 3, 16, 16, generator=g)
    with torch.no_grad():
        assert torch.allclose(nhwc(img), nchw(img), rtol=1e-5, atol=1e-6)


def test_bf16_chunk_casts_weights_once_and_stays_the_same_bit_for_bit(monkeypatch):
    # A chunk's 16 denoising steps reuse autocast's bfloat16 copies of the U-Net weights. The copies
    # are the same values, so the chunk must equal, bit for bit, one whose every U-Net call casts
    # afresh (what sampling did before); and the copies must not outlive the chunk: after the
    # weights change (as training changes them), the next chunk follows the new weights.
    import contextlib

    from torch.utils._python_dispatch import TorchDispatchMode

    from softvt_campaign.baselines.model import DiffusionPolicyModel, noise_scheduler

    cfg = make_config("vt-c", **{**TINY, "precision": "bf16"})
    torch.manual_seed(0)
    model = DiffusionPolicyModel(cfg, T.empty_stats(cfg)).eval()
    obs = random_window(cfg, model.image_keys, 1, torch.Generator().manual_seed(1))
    sample = lambda: model.sample(obs, torch.Generator().manual_seed(2), noise_scheduler(cfg, inference=True))
    real = type(model).weight_cast_cache

    weights = {p.data_ptr() for p in model.parameters()}

    class WeightCasts(TorchDispatchMode):  # counts each weight's copy into bfloat16
        def __init__(self):
            super().__init__()
            self.n = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            kwargs = kwargs or {}
            if func is torch.ops.aten._to_copy.default and kwargs.get("dtype") == torch.bfloat16 \
                    and args[0].data_ptr() in weights:
                self.n += 1
            return func(*args, **kwargs)

    def both() -> tuple[torch.Tensor, torch.Tensor]:
        monkeypatch.setattr(type(model), "weight_cast_cache", real)
        with WeightCasts() as once:
            cached = sample()
        monkeypatch.setattr(type(model), "weight_cast_cache", lambda self: contextlib.nullcontext())
        with WeightCasts() as per_call:
            fresh = sample()
        # each U-Net weight once per chunk instead of once per denoising call (16 of them)
        assert 0 < once.n < per_call.n / 2
        return cached, fresh

    cached, fresh = both()
    assert torch.isfinite(cached).all() and torch.equal(cached, fresh)
    assert not torch.is_autocast_enabled("cpu")
    with torch.no_grad():
        for p in model.unet.parameters():
            p.mul_(1.01)
    cached2, fresh2 = both()
    assert torch.equal(cached2, fresh2) and not torch.equal(cached2, cached)
    fp32 = make_config("vt-c", **{**TINY, "precision": "fp32"})
    assert isinstance(DiffusionPolicyModel(fp32, T.empty_stats(fp32)).weight_cast_cache(), contextlib.nullcontext)


def _bf16_product_cases(g: torch.Generator) -> dict:
    """Each kind of product the networks take, with a bias: (function, bfloat16-exact float32
    operands, the most terms any of its sums (output, each gradient) adds)."""
    from torch.nn import functional as F

    def r(*shape, scale=1.0):  # values bfloat16 holds exactly, so autocast's cast keeps them
        return (scale * torch.randn(*shape, generator=g)).to(torch.bfloat16).float()

    return {
        "conv2d, channels-last": (lambda x, w, b: F.conv2d(x, w, b, padding=1),
                                  (r(8, 32, 12, 12).contiguous(memory_format=torch.channels_last), r(24, 32, 3, 3, scale=0.1),
                                   r(24)), 8 * 12 * 12),
        "conv1d": (lambda x, w, b: F.conv1d(x, w, b, padding=2), (r(8, 32, 20), r(24, 32, 5, scale=0.1), r(24)), 32 * 5 + 1),
        "conv_transpose1d": (lambda x, w, b: F.conv_transpose1d(x, w, b, stride=2, padding=1),
                             (r(8, 24, 10), r(24, 16, 4, scale=0.1), r(16)), 8 * 19),
        "linear": (lambda x, w, b: F.linear(x, w, b), (r(64, 96), r(40, 96, scale=0.1), r(40)), 97),
        "linear, 3-D input": (lambda x, w, b: F.linear(x, w, b), (r(4, 16, 96), r(40, 96, scale=0.1), r(40)), 97),
    }


def test_float32_products_are_bfloat16_products_accumulated_in_float32_and_rounded_once():
    # The semantics of oneDNN's bfloat16 kernels on CPUs with AVX-512 BF16 or AMX, with float32
    # kernels: each product's output is bfloat16, and the output and every gradient (input, weight,
    # bias) are within one rounding of a float32 sum of the exact products: half a bfloat16 unit
    # (2^-8 relative) plus float32's summation error over n terms, n 2^-24 times the sum of the
    # terms' magnitudes (the 1.01 covers rounding the float32 sum rather than the exact one). The
    # exact values and the magnitudes are float64 autograd on the same operands (and on their
    # absolute values: every product here is linear in each operand). A kernel that rounds each
    # product, sums in bfloat16 or rounds twice misses the bound on hundreds of elements here.
    from softvt_campaign.baselines.bf16 import Float32Products

    for name, (fn, operands, n_terms) in _bf16_product_cases(torch.Generator().manual_seed(0)).items():
        leaves = [t.clone().requires_grad_() for t in operands]
        with Float32Products() as mode, torch.autocast("cpu", torch.bfloat16):
            out = fn(*leaves)
        grad = torch.randn(out.shape, generator=torch.Generator().manual_seed(1)).to(torch.bfloat16)
        with Float32Products():
            out.backward(grad)
        assert out.dtype == torch.bfloat16 and mode.calls >= 1, name
        exact = [t.double().requires_grad_() for t in operands]
        magnitude = [t.double().abs().requires_grad_() for t in operands]
        exact_out, magnitude_out = fn(*exact), fn(*magnitude)
        exact_out.backward(grad.double())
        magnitude_out.backward(grad.double().abs())
        pairs = [("output", out, exact_out, magnitude_out)] + [
            (f"gradient {i}", leaf.grad, e.grad, m.grad) for i, (leaf, e, m) in enumerate(zip(leaves, exact, magnitude))]
        for part, got, want, size in pairs:
            bound = 2.0 ** -8 * want.detach().abs() + 1.01 * n_terms * 2.0 ** -24 * size.detach()
            assert bool(((got.detach().double() - want.detach()).abs() <= bound).all()), (name, part)


def test_a_training_step_under_float32_products_leaves_no_bfloat16_product_to_the_native_kernels(tmp_path):
    # The mode handles the operators in bf16.PRODUCTS; a product the networks reached by another
    # operator would run the native kernels unseen. Below the mode, no bfloat16 product may arrive.
    from torch.utils._python_dispatch import TorchDispatchMode

    products = {"mm", "addmm", "bmm", "baddbmm", "addbmm", "mv", "addmv", "dot", "vdot", "matmul", "linear", "einsum",
                "outer", "addr", "convolution", "convolution_backward", "_convolution", "mkldnn_convolution",
                "_slow_conv2d_forward", "_slow_conv2d_backward", "mkldnn_linear", "_addmm_activation", "prelu",
                "_scaled_dot_product_attention_math", "_scaled_dot_product_flash_attention_for_cpu"}

    class Below(TorchDispatchMode):  # entered first, so it sees what the mode above hands down
        def __init__(self):
            super().__init__()
            self.bf16, self.float32 = set(), set()

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            name = func.overloadpacket.__name__
            if name in products:
                dtypes = {a.dtype for a in args if isinstance(a, torch.Tensor)}
                (self.bf16 if torch.bfloat16 in dtypes else self.float32).add(name)
            return func(*args, **(kwargs or {}))

    _write_demos(tmp_path / "demos")
    for variant in ("vo-c", "vt-c"):
        cfg = make_config(variant, **TINY)
        windows = load_windows(cfg, tmp_path / "demos", None)
        run = T.Training(cfg, windows.stats(), cfg.steps, bf16_products="float32")
        with Below() as below:
            run.train_step(windows)
        assert below.bf16 == set(), variant
        assert {"convolution", "convolution_backward", "mm", "addmm"} <= below.float32, variant


def test_bf16_products_are_native_only_where_the_cpu_has_bfloat16_instructions():
    from softvt_campaign.baselines.bf16 import choose_products

    assert choose_products("auto", "bf16", {"avx2", "fma"}) == "float32"
    assert choose_products("auto", "bf16", {"avx512f", "avx512_bf16"}) == "native"
    assert choose_products("auto", "bf16", {"amx_bf16"}) == "native"
    assert choose_products("native", "bf16", {"avx2"}) == "native"
    assert choose_products("float32", "bf16", {"amx_bf16"}) == "float32"
    assert choose_products("auto", "fp32", {"avx2"}) is None
    with pytest.raises(ValueError, match="'fp16'.*auto"):
        choose_products("fp16", "bf16")


def test_a_run_counts_its_steps_by_bf16_products_and_resumes_bit_for_bit_under_float32_products(tmp_path):
    _write_demos(tmp_path / "demos")
    cfg = make_config("vt-c", **TINY)  # the cpu preset: bf16
    straight = T.train(cfg, tmp_path / "demos", tmp_path / "a", progress=False, bf16_products="float32")
    T.train(cfg, tmp_path / "demos", tmp_path / "b", stop_after=3, progress=False, bf16_products="float32")
    resumed = T.train(cfg, tmp_path / "demos", tmp_path / "b", progress=False, bf16_products="float32")
    a, b = torch.load(straight, weights_only=False), torch.load(resumed, weights_only=False)
    assert all(torch.equal(a["model"][k], b["model"][k]) for k in a["model"])
    assert a["bf16_product_steps"] == b["bf16_product_steps"] == {"float32": cfg.steps}
    # A run resumed on a machine of the other kind says how many steps each trained.
    T.train(cfg, tmp_path / "demos", tmp_path / "c", stop_after=4, progress=False, bf16_products="float32")
    mixed = torch.load(T.train(cfg, tmp_path / "demos", tmp_path / "c", progress=False), weights_only=False)
    assert mixed["bf16_product_steps"] == {"float32": 4, "native": cfg.steps - 4}
    # A checkpoint from before the choice trained natively throughout.
    ckpt = torch.load(tmp_path / "c" / T.CHECKPOINT, weights_only=False)
    del ckpt["bf16_product_steps"]
    run = T.Training(cfg, T.empty_stats(cfg), cfg.steps)
    run.load(ckpt)
    assert run.bf16_product_steps == {"native": cfg.steps}
    with pytest.raises(ValueError, match="bf16_products 'auto'"):
        T.Training(cfg, T.empty_stats(cfg), cfg.steps, bf16_products="auto")


def test_paper_preset_has_the_papers_parameter_count():
    # Appendix, table of VO/VT variants: Diffusion Policy VO has 329.2M trainable parameters.
    from softvt_campaign.baselines.model import DiffusionPolicyModel

    cfg = make_config("vo-c", "paper")
    n = sum(p.numel() for p in DiffusionPolicyModel(cfg, T.empty_stats(cfg)).parameters())
    assert abs(n / 329.2e6 - 1) < 0.01


# ----------------------------------------------------------------------------------- windows

def test_windows_pad_at_the_episode_edges_and_never_cross_them(tmp_path):
    _write_demos(tmp_path)
    cfg = make_config("vt-c", **TINY)
    w = load_windows(cfg, tmp_path, None)
    assert len(w) == 15 and w.episodes == 2 and w.frames["base"].shape == (17, 16, 16, 3)
    assert w.frames["tactile_left"].shape == (17, 12, 16, 4) and w.frames["markers"].shape == (17, 2, 99, 2)
    obs, act = w.batch(np.array([0, 8, 9]))
    # Step 0 repeats its frame as the previous one; step 8 (the last of episode 0) sees 7 and 8.
    assert torch.equal(obs["base"][0, 0], obs["base"][0, 1])
    np.testing.assert_array_equal(obs["state"][1].numpy(), w.frames["state"][[7, 8]])
    # Its action chunk holds the episode's last action; step 9 is episode 1's first step.
    assert torch.equal(act[1], torch.from_numpy(np.repeat(w.actions[8:9], 16, 0)))
    assert torch.equal(obs["state"][2, 0], torch.from_numpy(w.frames["state"][10]))
    np.testing.assert_array_equal(act[2, :6].numpy(), w.actions[9:15])
    # The binary variant reads the binary gripper column.
    wb = load_windows(make_config("vo-b", **TINY), tmp_path, None)
    assert set(np.unique(wb.actions[:, 6])) == {0.0, 1.0} and "markers" not in wb.frames


def test_windows_cache_is_reused_and_rebuilt_when_the_inputs_change(tmp_path, monkeypatch):
    ds = _write_demos(tmp_path / "demos")
    cfg = make_config("vo-c", **TINY)
    cache = tmp_path / "cache"
    w1 = load_windows(cfg, tmp_path / "demos", cache)
    entry = cache / w1.key
    mtime = (entry / "meta.json").stat().st_mtime_ns
    assert isinstance(w1.frames["base"], np.memmap)  # read from the files, not held in memory
    fresh = load_windows(cfg, tmp_path / "demos", None)
    assert all(np.array_equal(fresh.frames[k], w1.frames[k]) for k in fresh.frames)
    assert np.array_equal(fresh.actions, w1.actions) and fresh.camera_render_size == w1.camera_render_size
    monkeypatch.chdir(tmp_path)  # the same files named by a relative path are the same data
    w2 = load_windows(cfg, Path("demos"), cache)
    assert (entry / "meta.json").stat().st_mtime_ns == mtime and np.array_equal(w1.frames["base"], w2.frames["base"])
    # Another run reading the same episodes the same way shares the entry; other inputs get their own.
    assert load_windows(make_config("vo-c", **{**TINY, "lr": 1e-3}), tmp_path / "demos", cache).key == w1.key
    w3 = load_windows(make_config("vo-c", **{**TINY, "camera_size": (8, 8)}), tmp_path / "demos", cache)
    entries = sorted(p.name for p in cache.iterdir() if not p.name.startswith("."))
    assert w3.frames["base"].shape[1:3] == (8, 8) and entries == sorted([w1.key, w3.key])
    from softvt_campaign.baselines import dataset as D

    # Arrays another entry holds byte for byte are shared (hard links), the rest are the entry's own:
    # the 8x8 entry reads the same state and actions but other camera frames.
    ino = lambda key, name: (cache / key / f"{name}.npy").stat().st_ino
    assert ino(w3.key, "frame_state") == ino(w1.key, "frame_state") and ino(w3.key, "actions") == ino(w1.key, "actions")
    assert ino(w3.key, "frame_base") != ino(w1.key, "frame_base")
    # VT on the same demos shares VO's cameras and actions and holds its touch alone, the same
    # arrays as prepared without a cache; the binary variant's actions are its own.
    vt_c = load_windows(make_config("vt-c", **TINY), tmp_path / "demos", cache)
    assert ino(vt_c.key, "frame_base") == ino(w1.key, "frame_base") and ino(vt_c.key, "actions") == ino(w1.key, "actions")
    vt_fresh = load_windows(make_config("vt-c", **TINY), tmp_path / "demos", None)
    assert all(np.array_equal(vt_fresh.frames[k], vt_c.frames[k]) for k in vt_fresh.frames)
    assert np.array_equal(vt_fresh.actions, vt_c.actions)
    vo_b = load_windows(make_config("vo-b", **TINY), tmp_path / "demos", cache)
    assert ino(vo_b.key, "frame_base") == ino(w1.key, "frame_base") and ino(vo_b.key, "actions") != ino(w1.key, "actions")
    # VO's files are all inside VT's entry now: counted once, they add nothing to its size.
    assert D.cache_size_gb([cache / w1.key, cache / vt_c.key]) == pytest.approx(D.cache_size_gb([cache / vt_c.key]))
    # Deleting the entry that first held the shared files leaves the others whole.
    shutil.rmtree(cache / w1.key)
    again = load_windows(make_config("vt-c", **TINY), tmp_path / "demos", cache)
    assert all(np.array_equal(vt_fresh.frames[k], again.frames[k]) for k in vt_fresh.frames)
    assert np.array_equal(vt_fresh.actions, again.actions)
    # Without hard links (a filesystem that refuses them) an entry keeps its own copies.
    shutil.rmtree(cache / vo_b.key)
    with monkeypatch.context() as m:
        m.setattr(D.os, "link", lambda *a: (_ for _ in ()).throw(PermissionError(1, "no links")))
        vo_b2 = load_windows(make_config("vo-b", **TINY), tmp_path / "demos", cache)
    assert ino(vo_b2.key, "frame_base") != ino(vt_c.key, "frame_base")
    assert np.array_equal(vo_b2.frames["base"], vt_fresh.frames["base"])
    w1 = load_windows(cfg, tmp_path / "demos", cache)
    # A temporary directory of a process that died is removed; an older version's cache file is refused.

    dead = cache / f".{w3.key}.tmp-999999999"
    (dead / "frame_base.npy").parent.mkdir()
    shutil.rmtree(cache / w3.key)
    cfg8 = make_config("vo-c", **{**TINY, "camera_size": (8, 8)})
    load_windows(cfg8, tmp_path / "demos", cache)
    assert not dead.exists() and (cache / w3.key / "meta.json").exists()
    # A process preparing the same key holds its lock: the others wait for it and read its result.
    import subprocess
    import sys
    import time as _time

    shutil.rmtree(cache / w3.key)
    hold = ("import fcntl, sys, time; f = open(sys.argv[1], 'a'); "
            "fcntl.flock(f, fcntl.LOCK_EX); print('locked', flush=True); time.sleep(1.0)")
    holder = subprocess.Popen([sys.executable, "-c", hold, str(cache / f".{w3.key}.lock")], stdout=subprocess.PIPE,
                              text=True)
    assert holder.stdout.readline().strip() == "locked"
    t0 = _time.monotonic()
    load_windows(cfg8, tmp_path / "demos", cache)
    holder.wait()
    assert _time.monotonic() - t0 >= 0.5 and (cache / w3.key / "meta.json").exists()
    # A package that renders or reads touch otherwise never reads an entry prepared by this one.
    vt = make_config("vt-c", **TINY)
    before = D.data_key(vt, tmp_path / "demos")
    monkeypatch.setattr("mani_skill_softvt.tasks.suites.model_version", lambda deformable: TACTILE_MODEL_VERSION + 1)
    assert D.data_key(vt, tmp_path / "demos") != before
    (tmp_path / "old.npz").write_bytes(b"x")
    with pytest.raises(ValueError, match="older version"):
        load_windows(cfg, tmp_path / "demos", tmp_path / "old.npz")
    with pytest.raises(FileNotFoundError, match="demos render"):
        ds.rendered(0, "rgb+tactile").unlink()
        load_windows(cfg, tmp_path / "demos", None)


def test_the_rendering_read_is_the_policys_size_or_the_smallest_larger_one():
    from softvt_campaign.baselines.dataset import render_size_for

    available = [(84, 84), (128, 128), (224, 224)]
    assert render_size_for((84, 84), available) == (84, 84)
    assert render_size_for((64, 64), available) == (84, 84)  # shrunk from the nearest larger
    assert render_size_for((96, 96), available) == (128, 128)
    assert render_size_for((96, 160), available) == (224, 224)
    assert render_size_for((256, 256), available) == (256, 256)  # never enlarged: its file is missing
    assert render_size_for((84, 84), []) == (84, 84)


def test_training_reads_the_rendering_at_the_policys_camera_size_and_evaluation_renders_it_again(tmp_path):
    """Demos rendered at the policy's camera size are read as they are (no resizing), and the
    trained policy asks the evaluator for that size; trained on the native 224x224 rendering
    (shrunk), it asks for nothing."""
    root = tmp_path / "demos"
    _write_demos(root)
    cfg = make_config("vo-c", **TINY)
    native = load_windows(cfg, root, None)
    assert native.camera_render_size == (224, 224) and native.frames["base"].shape[1:3] == (16, 16)
    assert load_policy(str(T.train(cfg, root, tmp_path / "native", progress=False))).camera_size is None

    ds = _write_demos(root, camera_size=(16, 16))
    sized = load_windows(cfg, root, tmp_path / "cache")
    assert sized.camera_render_size == (16, 16)
    with h5py.File(ds.rendered(0, "rgb+tactile", (16, 16)), "r") as f:
        stored = f["traj_0/obs/sensor_data/base_camera/rgb"][()]
    assert np.array_equal(sized.frames["base"][:len(stored)], stored)  # the pixels as rendered
    assert load_windows(cfg, root, tmp_path / "cache").camera_render_size == (16, 16)  # from the cache
    path = T.train(cfg, root, tmp_path / "sized", progress=False)
    assert torch.load(path, weights_only=False)["camera_render_size"] == [16, 16]
    assert load_policy(str(path)).camera_size == (16, 16)
    assert ds.rendered(0, "rgb+tactile", (16, 16)).name == "task0_rgb_tactile_16x16.h5"
    assert ds.rendered(0, "rgb+tactile", (224, 224)) == ds.rendered(0, "rgb+tactile")


# ---------------------------------------------------------------------------------- training

def test_batches_cover_each_epoch_once():
    cfg = make_config("vo-c", batch_size=4)
    seen = np.concatenate([T.batch_indices(cfg, 12, s) for s in range(3)])
    assert sorted(seen) == list(range(12))
    assert not np.array_equal(seen, np.concatenate([T.batch_indices(cfg, 12, s) for s in range(3, 6)]))


def test_random_shift_moves_whole_frames_within_the_pad():
    g = torch.Generator().manual_seed(0)
    img = torch.zeros(3, 2, 20, 20, 1, dtype=torch.uint8)
    img[:, :, 10, 10] = 255
    out = random_shift(img, 4, g)
    for b in range(3):
        (y0, x0), (y1, x1) = [torch.nonzero(out[b, t, ..., 0]).squeeze(0).tolist() for t in range(2)]
        assert (y0, x0) == (y1, x1) and abs(y0 - 10) <= 4 and abs(x0 - 10) <= 4  # same shift for both frames


random_shift = T.random_shift


def test_a_time_budget_stops_at_a_checkpoint_and_snapshots_are_policies(tmp_path):
    _write_demos(tmp_path / "demos")
    cfg = make_config("vo-c", **TINY)  # 6 steps, a checkpoint every 2
    run = tmp_path / "run"
    T.train(cfg, tmp_path / "demos", run, progress=False, deadline=0.0, snapshot_every=2)  # the budget is spent
    assert torch.load(run / T.CHECKPOINT, weights_only=False)["step"] == 2 and not (run / T.POLICY).exists()
    path = T.train(cfg, tmp_path / "demos", run, progress=False, snapshot_every=2)
    snaps = [T.snapshot_path(run, k) for k in (2, 4, 6)]
    assert sorted((run / "snapshots").iterdir()) == snaps and snaps[0].name == "run_step000002.pt"
    files = [torch.load(p, weights_only=False) for p in snaps]
    assert [f["steps"] for f in files] == [2, 4, 6]
    assert 0 < files[0]["train_wall_s"] < files[1]["train_wall_s"] < files[2]["train_wall_s"]
    final = torch.load(path, weights_only=False)
    assert all(torch.equal(final["model"][k], files[2]["model"][k]) for k in final["model"])
    assert load_policy(str(snaps[1])).name == load_policy(str(path)).name  # a snapshot is a policy


def test_training_resumes_bit_for_bit(tmp_path):
    _write_demos(tmp_path / "demos")
    cfg = make_config("vt-c", **TINY)
    straight = T.train(cfg, tmp_path / "demos", tmp_path / "a", progress=False)
    T.train(cfg, tmp_path / "demos", tmp_path / "b", stop_after=3, progress=False)  # stops between checkpoints
    assert not (tmp_path / "b" / T.POLICY).exists()
    resumed = T.train(cfg, tmp_path / "demos", tmp_path / "b", progress=False)
    a, b = torch.load(straight, weights_only=False), torch.load(resumed, weights_only=False)
    assert a["model"].keys() == b["model"].keys()
    assert all(torch.equal(a["model"][k], b["model"][k]) for k in a["model"])
    ca = torch.load(tmp_path / "a" / T.CHECKPOINT, weights_only=False)
    cb = torch.load(tmp_path / "b" / T.CHECKPOINT, weights_only=False)
    assert ca["losses"] == cb["losses"] and len(ca["losses"]) == cfg.steps
    assert (tmp_path / "a" / "loss.png").stat().st_size > 0
    mtime = straight.stat().st_mtime_ns
    assert T.train(cfg, tmp_path / "demos", tmp_path / "a", progress=False) == straight
    assert straight.stat().st_mtime_ns == mtime  # a finished run is left as it is
    # Another configuration in the same directory is refused, naming the difference; so are
    # demonstrations rendered again since (other normalisers, other batches).
    with pytest.raises(ValueError, match="batch_size"):
        T.train(make_config("vt-c", **{**TINY, "batch_size": 2}), tmp_path / "demos", tmp_path / "a", progress=False)
    (tmp_path / "b" / T.POLICY).unlink()
    ckpt = torch.load(tmp_path / "b" / T.CHECKPOINT, weights_only=False)
    T.save(tmp_path / "b" / T.CHECKPOINT, {**ckpt, "step": 3})  # an unfinished run
    _write_demos(tmp_path / "demos2", seed=1)
    with pytest.raises(ValueError, match="other demonstration files"):
        T.train(cfg, tmp_path / "demos2", tmp_path / "b", progress=False)


@pytest.mark.slow  # about a minute of physics or training on 2 cores; CI runs it (-m slow)
def test_diffusion_learns_the_demonstrated_chunk(tmp_path):
    # One demo whose chunk at a step is set by the state (x ramps with the step; the other columns
    # are constant). Sampled from the same noise, the trained policy's chunk must be far closer to
    # the demonstrated one than the untrained network's (in normalised units, where the action
    # box is [-1, 1] and an untrained sampler lands anywhere in it).
    _write_demos(tmp_path / "demos", lengths=(40,))
    from softvt_campaign.baselines.model import noise_scheduler

    cfg = make_config("vo-c", **{**TINY, "steps": 400, "checkpoint_every": 400, "lr": 1e-3, "warmup_steps": 10,
                                 "unet_dims": (64, 128), "unet_groups": 8, "batch_size": 8})
    w = load_windows(cfg, tmp_path / "demos", None)
    untrained = T.Training(cfg, w.stats(), cfg.steps).model.eval()
    _, trained, _ = load_policy_file(T.train(cfg, tmp_path / "demos", tmp_path / "run", progress=False))
    obs, act = w.batch(np.array([20]))

    def error(model):
        chunk = model.sample(obs, torch.Generator().manual_seed(1), noise_scheduler(cfg, inference=True))
        norm = trained.normalize["action"]
        return float((norm(chunk) - norm(act)).abs().mean())

    assert error(trained) < 0.4 * error(untrained), (error(trained), error(untrained))


def test_action_errors_measure_distance_rotation_angle_and_closure():
    from scipy.spatial.transform import Rotation

    from softvt_campaign.studies.openloop import action_errors

    target = np.r_[0.5, 0.0, 0.2, down_rotvec(0.3), 0.4][None]
    pred = target.copy()
    pred[0, :3] += [0.003, 0.004, 0.0]  # 5 mm
    turned = Rotation.from_rotvec(target[0, 3:6]) * Rotation.from_rotvec([0.0, 0.0, np.radians(10)])
    pred[0, 3:6] = turned.as_rotvec()
    pred[0, 6] = 0.9
    e = action_errors(pred, target)
    np.testing.assert_allclose(e["position_m"], [0.005], atol=1e-12)
    np.testing.assert_allclose(e["rotation_rad"], [np.radians(10)], atol=1e-9)
    np.testing.assert_allclose(e["gripper"], [0.5], atol=1e-12)
    # The half turn's two axis-angle branches are one orientation: no error across the jump.
    flipped = target.copy()
    r = target[0, 3:6]
    flipped[0, 3:6] = r - 2 * np.pi * r / np.linalg.norm(r)
    assert action_errors(flipped, target)["rotation_rad"][0] < 1e-9


def test_heldout_demos_are_never_trained_on_and_the_openloop_check_reads_them(tmp_path):
    from softvt_campaign.studies.openloop import main as openloop_main
    from softvt_campaign.studies.openloop import replan_indices

    _write_demos(tmp_path / "demos", lengths=(9, 6, 7))
    cfg = make_config("vo-c", **{**TINY, "heldout_per_task": 1})
    train = load_windows(cfg, tmp_path / "demos", None)
    held = load_windows(cfg, tmp_path / "demos", None, heldout=True)
    assert (train.episodes, len(train), held.episodes, len(held)) == (2, 15, 1, 7)
    assert list(replan_indices(held, 8)) == [0] and list(replan_indices(train, 8)) == [0, 8, 9]
    from softvt_campaign.baselines.dataset import split_episodes

    names = [f"traj_{i}" for i in range(40)]
    fixed = make_config("vo-c", demos_per_task=30, heldout_per_task=5)
    assert split_episodes(names, fixed) == names[:30] and split_episodes(names, fixed, heldout=True) == names[30:35]
    assert split_episodes(names + ["traj_40"], fixed, heldout=True) == names[30:35]  # the set grew: the same split
    with pytest.raises(ValueError, match="task0.h5: 34 demos.*trains on 30 and holds out 5"):
        split_episodes(names[:34], fixed, where="task0.h5")
    path = T.train(cfg, tmp_path / "demos", tmp_path / "run", progress=False)
    result = openloop_main([str(path), "--demos", str(tmp_path / "demos"), "--threads", "1"])
    assert result["heldout"]["windows"] == 1 and result["training"]["windows"] == 3
    assert json.loads((tmp_path / "run" / "openloop.json").read_text())["episodes_heldout"] == 1
    untouched = T.train(make_config("vo-c", **TINY), tmp_path / "demos", tmp_path / "all", progress=False)
    with pytest.raises(SystemExit):
        openloop_main([str(untouched), "--demos", str(tmp_path / "demos")])
    # The prepared data's key names the episodes read: the set grew, the key stays (a run resumes).
    from softvt_campaign.baselines.dataset import _sources, cache_key

    small = make_config("vo-c", **{**TINY, "demos_per_task": 1, "heldout_per_task": 1})
    before = cache_key(small, _sources(small, tmp_path / "demos"))
    _write_demos(tmp_path / "demos", lengths=(9, 6, 7, 5))
    assert cache_key(small, _sources(small, tmp_path / "demos")) == before
    assert cache_key(small, _sources(small, tmp_path / "demos"), heldout=True) != before
    with pytest.raises(SystemExit):  # the demos the run trained on changed: its held-out ones may not be
        openloop_main([str(path), "--demos", str(tmp_path / "demos"), "--threads", "1"])


def test_the_recipe_search_logs_each_snapshots_openloop_error_once_and_resumes(tmp_path, monkeypatch, capsys):
    from softvt_campaign.studies import recipe_search as search

    _write_demos(tmp_path / "demos", lengths=(9, 6, 7))
    monkeypatch.setitem(search.RECIPES, "tiny", {k: v for k, v in TINY.items() if k != "threads"})
    argv = ["--recipes", "tiny", "--heldout", "1", "--snapshot-every", "2", "--demos", str(tmp_path / "demos"),
            "--runs", str(tmp_path / "runs"), "--results", str(tmp_path / "results")]
    search.main(argv + ["--budget-min", "0.0001"])  # the budget is spent at the first checkpoint
    assert "ran out" in capsys.readouterr().out
    assert [r["step"] for r in search.measured("vo-c", tmp_path / "results").values()] == [2]
    search.main(argv)  # resumes, measures the later snapshots only
    rows = {r["step"]: r for r in search.measured("vo-c", tmp_path / "results").values()}
    assert sorted(rows) == [2, 4, 6] and len({r["run"] for r in rows.values()}) == 1
    assert all(r["episodes_heldout"] == 1 and r["episodes_trained"] == 2 and r["recipe"] == "tiny" for r in rows.values())
    assert rows[6]["train_wall_s"] >= rows[2]["train_wall_s"]
    assert (tmp_path / "runs" / "vo-c" / "vo-c-tiny" / "snapshots" / "vo-c-tiny_step000004.pt").exists()
    search.main(argv)  # nothing new
    assert len((tmp_path / "results" / "vo-c.jsonl").read_text().splitlines()) == 3
    assert f"| tiny ({rows[6]['run'][:6]}) | 2 / 1 | 6 |" in search.main(["--results", str(tmp_path / "results"), "--table"])
    # Another held-out split (or an edited recipe) is another run: its results never hide behind these.
    cfg = search.search_config("vo-c", "tiny", 1)
    assert search.run_id(cfg, "k") != search.run_id(search.search_config("vo-c", "tiny", 2), "k")
    # A recipe that differs only in how it samples (exec4 of long) takes the other's weights, untrained.
    monkeypatch.setitem(search.RECIPES, "tiny4", {**search.RECIPES["tiny"], "action_steps": 4})
    search.main(argv + ["--recipes", "tiny", "tiny4"])
    derived = tmp_path / "runs" / "vo-c" / "vo-c-tiny4"
    assert not (derived / T.CHECKPOINT).exists() and [search.snapshot_step(p) for p in search.run_snapshots(derived)] == [2, 4, 6]
    a = torch.load(tmp_path / "runs" / "vo-c" / "vo-c-tiny" / T.POLICY, weights_only=False)
    b = torch.load(derived / T.POLICY, weights_only=False)
    assert b["config"]["action_steps"] == 4 and all(torch.equal(a["model"][k], b["model"][k]) for k in a["model"])
    rows4 = [r for r in search.measured("vo-c", tmp_path / "results").values() if r["recipe"] == "tiny4"]
    assert sorted(r["step"] for r in rows4) == [2, 4, 6] and rows4[0]["run"] != rows[6]["run"]
    # --set names the run by the parsed values in key order; the search's own fields are refused.
    assert search.recipe_label("long", {"lr": 0.001, "camera_size": (96, 96)}) == "long+camera_size=96,96+lr=0.001"
    with pytest.raises(SystemExit):
        search.main(argv + ["--set", "threads=4"])
    with pytest.raises(SystemExit):
        search.main(argv + ["--steps", "6"])  # --steps without --closed-loop
    assert search.run_id(cfg, "k") != search.run_id(cfg, "other demos")


# ------------------------------------------------------------------------------------- agent

def _env_obs(rng, tactile: bool) -> dict:
    obs = {"agent": {"qpos": torch.tensor([[0.0] * 7 + [0.04, 0.04]])},
           "extra": {"tcp_pose": torch.from_numpy(np.r_[0.0, 0.0, 0.2, down_quat(0.0)][None].astype(np.float32)),
                     "gripper_width": torch.full((1, 1), 0.08)},
           "sensor_data": {c: {"rgb": torch.from_numpy(rng.integers(0, 256, (1, 224, 224, 3), dtype=np.uint8))}
                           for c in ("base_camera", "hand_camera")}}
    if tactile:
        obs["tactile"] = {s: {"rgb": torch.from_numpy(rng.integers(0, 256, (1, 240, 320, 3), dtype=np.uint8)),
                              "depth": torch.zeros(1, 240, 320, dtype=torch.int16),
                              "marker_initial": torch.zeros(1, 99, 2), "marker_current": torch.zeros(1, 99, 2)}
                          for s in ("left", "right")}
    return obs


@pytest.mark.parametrize("variant", ["vt-b", "vo-c"])
def test_agent_replans_every_action_steps_and_is_deterministic(tmp_path, variant):
    _write_demos(tmp_path / "demos")
    path = T.train(make_config(variant, **TINY), tmp_path / "demos", tmp_path / "run", progress=False)
    policy = load_policy(str(path))
    tactile = variant.startswith("vt")
    assert isinstance(policy, DiffusionPolicyAgent)
    assert policy.name == f"diffusion_policy[{variant},cpu{',rgb+depth' if tactile else ''}]"
    runs = []
    sample = policy.model.sample
    for _ in range(2):
        rng = np.random.default_rng(0)
        policy.reset("pick", seed=5)
        calls = []
        policy.model.sample = lambda *a: calls.append(1) or sample(*a)
        runs.append(np.concatenate([policy.act(_env_obs(rng, tactile)) for _ in range(17)]))
        assert len(calls) == 3  # steps 0, 8 and 16
    assert runs[0].shape == (17, 7) and np.array_equal(runs[0], runs[1])
    g = runs[0][:, 6]
    assert set(np.unique(g)) <= {0.0, 1.0} if variant.endswith("-b") else ((0 <= g) & (g <= 1)).all()
    if variant.startswith("vt"):
        with pytest.raises(ValueError, match="tactile"):
            policy.reset("pick", seed=5)
            policy.act(_env_obs(np.random.default_rng(0), tactile=False))


def test_agent_reads_only_the_frames_it_plans_from(tmp_path, monkeypatch):
    """The agent asks for camera images only for the last obs_horizon frames before each
    replanning; given observations without images elsewhere, it acts exactly as an agent that
    reads every frame does with all of them."""
    _write_demos(tmp_path / "demos")
    policy = load_policy(str(T.train(make_config("vt-c", **TINY), tmp_path / "demos", tmp_path / "run", progress=False)))
    h, k = policy.cfg.obs_horizon, policy.cfg.action_steps
    assert (h, k) == (2, 8)
    runs, asked = [], []
    for blind in (False, True):
        if not blind:
            monkeypatch.setattr(policy, "_reads_frame", lambda: True)  # the reference reads every frame
        else:
            monkeypatch.undo()
        rng = np.random.default_rng(0)
        policy.reset("pick", seed=5)
        actions, wants = [], True
        for _ in range(17):
            obs = _env_obs(rng, tactile=True)
            if blind and not wants:
                obs["sensor_data"] = {}  # what the evaluator passes when it renders no camera
            actions.append(policy.act(obs))
            wants = policy.needs_next_images()
            asked.append(wants) if blind else None
        runs.append(np.concatenate(actions))
    assert np.array_equal(runs[0], runs[1])
    # The plans at calls 8 and 16 read the frames of calls 7, 8 and 15, 16, asked for by the calls before.
    assert [i for i, a in enumerate(asked) if a] == [6, 7, 14, 15]


def test_loading_a_policy_file_says_what_is_wrong(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.pt.*baselines.train"):
        load_policy(str(tmp_path / "missing.pt"))
    _write_demos(tmp_path / "demos")
    T.train(make_config("vo-c", **TINY), tmp_path / "demos", tmp_path / "run", stop_after=2, progress=False)
    with pytest.raises(ValueError, match="training state"):
        load_policy(str(tmp_path / "run" / T.CHECKPOINT))
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="bad.pt cannot be read") as e:
        load_policy(str(tmp_path / "bad.pt"))
    assert "export it again" in str(e.value) and "--out" not in str(e.value)  # not the trainer's advice


def test_touch_inputs_of_another_tactile_model_are_refused(tmp_path):
    # Frames rendered before the tactile model changed (no version kept: model 1) cannot train a
    # VT policy; a VO policy does not read them. A VT policy file of another model is refused.
    _write_demos(tmp_path / "old", tactile_model=None)
    with pytest.raises(ValueError, match="tactile frames of model 1.*demos render"):
        load_windows(make_config("vt-c", **TINY), tmp_path / "old", None)
    load_windows(make_config("vo-c", **TINY), tmp_path / "old", None)
    _write_demos(tmp_path / "demos")
    path = T.train(make_config("vt-c", **TINY), tmp_path / "demos", tmp_path / "run", progress=False)
    ckpt = torch.load(path, weights_only=False)
    assert ckpt["tactile_model"] == TACTILE_MODEL_VERSION
    del ckpt["tactile_model"]
    torch.save(ckpt, tmp_path / "old.pt")
    with pytest.raises(ValueError, match="old.pt was trained on tactile frames of model 1"):
        load_policy(str(tmp_path / "old.pt"))
    # Nor evaluated on a suite whose touch is rendered in another model (the rigid twins', 3).
    from mani_skill_softvt.evaluation.run import RunConfig

    RunConfig.resolve(str(path), suite="object_soft")
    with pytest.raises(ValueError, match=f"model {TACTILE_MODEL_VERSION}, and suite object_rigid renders model "
                                         f"{SUITES['object_rigid'].tactile_model}"):
        RunConfig.resolve(str(path), suite="object_rigid")
    # Object-Soft's frames are not the rigid twins': the same file declared an Object-Rigid policy is refused.
    ckpt["tactile_model"] = TACTILE_MODEL_VERSION
    ckpt["config"]["suite"] = "object_rigid"
    torch.save(ckpt, tmp_path / "rigid.pt")
    assert SUITES["object_rigid"].tactile_model != TACTILE_MODEL_VERSION
    with pytest.raises(ValueError, match=f"renders object_rigid's in model {SUITES['object_rigid'].tactile_model}"):
        load_policy(str(tmp_path / "rigid.pt"))


def test_a_twins_touch_rendered_from_states_without_its_contact_wrenches_is_refused_for_training(tmp_path):
    # Such a rendering shows the pinched twin on a blank gel (docs/demos.md, Rendering).
    rigid = SUITES["object_rigid"].tactile_model
    _write_demos(tmp_path / "old", suite="object_rigid", tactile_model=rigid)
    with pytest.raises(ValueError, match="task0.h5:traj_0: recorded without the twins' contact wrenches.*record the demos again"):
        load_windows(make_config("vt-c", suite="object_rigid", **TINY), tmp_path / "old", None)
    load_windows(make_config("vo-c", suite="object_rigid", **TINY), tmp_path / "old", None)  # no touch read
    _write_demos(tmp_path / "new", suite="object_rigid", tactile_model=rigid, twin_contact=True)
    load_windows(make_config("vt-c", suite="object_rigid", **TINY), tmp_path / "new", None)


def test_evaluate_takes_the_modes_a_baseline_was_trained_for(tmp_path, capsys):
    from mani_skill_softvt.cli import evaluate

    _write_demos(tmp_path / "demos")
    path = T.train(make_config("vt-b", **TINY), tmp_path / "demos", tmp_path / "vt-b-tiny", progress=False)
    for flag, wrong, right in (("--obs-mode", "rgb", "rgb+tactile"), ("--control-mode", "pd_ee_pose", "pd_ee_pose_binary")):
        with pytest.raises(SystemExit):
            evaluate.main(["--policy", str(path), flag, wrong, "--out", str(tmp_path / "eval")])
        assert f"{flag} {right}" in capsys.readouterr().err


@pytest.mark.slow
def test_the_recipe_search_scores_snapshots_in_closed_loop_and_resumes(tmp_path, monkeypatch):
    from softvt_campaign.studies import recipe_search as search

    _write_demos(tmp_path / "demos", lengths=(9, 6, 7))
    monkeypatch.setitem(search.RECIPES, "tiny", {k: v for k, v in TINY.items() if k != "threads"})
    argv = ["--recipes", "tiny", "--heldout", "1", "--snapshot-every", "3", "--demos", str(tmp_path / "demos"),
            "--runs", str(tmp_path / "runs"), "--results", str(tmp_path / "results"), "--set", "lr=0.001"]
    search.main(argv)
    run = tmp_path / "runs" / "vo-c" / "vo-c-tiny+lr=0.001"
    assert [search.snapshot_step(p) for p in search.run_snapshots(run)] == [3, 6]
    (run / "snapshots" / ".vo-c-tiny_step000009.pt").write_bytes(b"")  # a write in progress is no snapshot
    assert [search.snapshot_step(p) for p in search.run_snapshots(run)] == [3, 6]
    with pytest.raises(ValueError, match="no snapshots of steps \\[9\\]"):
        search.evaluate_snapshots(run, 1, [9], 1, tmp_path / "results", tasks=[0])
    summaries = search.evaluate_snapshots(run, 1, [6], 1, tmp_path / "results", tasks=[0])
    (key, summary), = summaries.items()
    assert key[1] == 6 and summary["episodes"] == 1 and sum(summary["terminations"].values()) == 1
    assert 0 <= summary["dsr"] <= summary["tsr"] <= 1 and summary["tsr_ci95"][1] > 0.5  # one episode: a wide interval
    records = list((tmp_path / "results" / "closed_loop").glob("*/object_soft_id_vo-c-tiny*_step000006.jsonl"))
    assert len(records) == 1 and len(records[0].read_text().splitlines()) == 1
    search.evaluate_snapshots(run, 1, [6], 1, tmp_path / "results", tasks=[0])  # resumes: nothing runs again
    assert len(records[0].read_text().splitlines()) == 1
    table = search.format_table("vo-c", tmp_path / "results")
    row = next(line for line in table.splitlines() if line.startswith("| tiny+lr=0.001") and "| 6 |" in line)
    assert re.search(r"\| 1 \| \d+ \[\d+, \d+\] \| \d+ \[\d+, \d+\] \|$", row), row
    assert search.plot_curves("vo-c", tmp_path / "results").stat().st_size > 0


@pytest.mark.slow
def test_a_trained_baseline_runs_a_scored_episode(tmp_path):
    # End to end on the real env: the record names the variant and the modes it was resolved to.
    from mani_skill_softvt.cli import evaluate
    from mani_skill_softvt.evaluation.records import read_records

    _write_demos(tmp_path / "demos")
    path = T.train(make_config("vt-c", **TINY), tmp_path / "demos", tmp_path / "vt-c-tiny", progress=False)
    evaluate.main(["--policy", str(path), "--tasks", "3", "--out", str(tmp_path / "eval")])
    (rec,) = read_records(tmp_path / "eval" / "object_soft_id_vt-c-tiny.jsonl")
    assert rec["receipt"]["policy"] == "diffusion_policy[vt-c,cpu,rgb+depth]" and not rec["receipt"]["privileged"]
    assert (rec["obs_mode"], rec["control_mode"]) == ("rgb+tactile", "pd_ee_pose")
    assert rec["termination"] in ("timeout", "dropped", "success") and rec["error"] is None
    from mani_skill_softvt.fileio import file_sha256

    assert rec["policy_sha256"] == file_sha256(path)  # the record pins the weights it scored


def test_results_table_puts_each_variant_beside_the_paper(tmp_path):
    from softvt_campaign.studies import results as report
    from mani_skill_softvt.evaluation.records import record_hash

    def rec(variant, seed, success, r_max, policy="x.pt", sha="a" * 64):
        r = ({"suite": "object_soft", "task_id": 0, "condition": "id", "seed": seed, "success": success,
                      "dsr_success": success and r_max <= 1, "r_max": r_max, "termination": "success" if success else "timeout",
                      "receipt": {"policy": f"diffusion_policy[{variant}]"}, "policy": policy, "tau_o": 0.01,
                      "policy_sha256": sha, "deformation_trace": [0.0, 0.01 * r_max]})
        return {**r, "record_sha256": record_hash(r)}

    path, old = tmp_path / "r.jsonl", tmp_path / "old.jsonl"
    rows = [rec("vo-c", i, i < 4, 1.5 if i < 1 else 0.5) for i in range(10)] + [rec("vt-b", i, False, 0.1, policy="z.pt") for i in range(5)]
    rows += [rec("vo-c", i, True, 0.5, policy="y.pt", sha=s) for i, s in ((0, "b" * 64), (1, "c" * 64))]
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    died = {k: v for k, v in rec("vo-c", 10, False, 0.0).items() if k not in ("policy_sha256", "record_sha256")}
    died = {**died, "termination": "worker_died", "r_max": None, "receipt": {"privileged": False}}
    with path.open("a") as fh:  # a dead worker's record: no variant in its receipt, no hash (an older record)
        fh.write(json.dumps({**died, "record_sha256": record_hash(died)}) + "\n")
    old.write_text("".join(json.dumps(rec("vo-c", i, False, 0.2)) + "\n" for i in range(3)))
    out = report.main([str(path), "--legacy", str(old), "--out", str(tmp_path)])
    data = out["rows"]
    vo = data["object_soft/id/vo-c (x)"]
    assert (vo["episodes"], vo["tsr"], vo["dsr"], vo["gap_share_of_successes"]) == (11, 4 / 11, 3 / 11, 0.25)
    assert vo["terminations"]["worker_died"] == 1
    assert vo["gap_share_ci95"][0] < 0.25 < vo["gap_share_ci95"][1] and vo["paper"][1:] == (37.4, 33.6)
    assert data["object_soft/id/vt-b (z)"]["gap_share_ci95"] is None
    # Two files of one name scored (retrained in between) never pool; older records stay apart, marked.
    assert data["object_soft/id/vo-c (y) sha bbbbbbbb"]["episodes"] == 1
    assert data["object_soft/id/vo-c (x) [old physics]"]["episodes"] == 3
    text = (tmp_path / "results.md").read_text()
    assert "| object_soft | ID | vo-c (x) | 11 | 36.4 [" in text and "no successes" in text
    assert "| object_soft/id/vo-c (x) | 4 | 0 | 6 | 0 | 0 | 1 | 1 | 0 | 0.500 |" in text  # one squeeze past tolerance, no collapse
    assert "| 0 (soft_pastry001) | 36 / 27 of 11 |" in text  # per task, beside today's other variants
    # Paired on seeds 0-4: vo-c (x) succeeded in 4 the vt-b never did; exact McNemar 2 * (1/2)^4.
    pair = out["comparisons"]["object_soft/id: vo-c (x) vs vt-b (z)"]["success"]
    assert (pair["pairs"], pair["only_a"], pair["only_b"], pair["neither"]) == (5, 4, 0, 1)
    assert pair["p_value"] == pytest.approx(0.125) and pair["unpaired"] == 11 - 5
    assert not any("old physics" in k for k in out["comparisons"])  # never compared across physics
    assert (tmp_path / "success_traces.png").stat().st_size > 0
    # Legacy records alone: no per-task table, no comparison, no figure (the stale one goes).
    legacy_only = report.main(["--legacy", str(old), "--out", str(tmp_path)])
    assert legacy_only["comparisons"] == {} and not (tmp_path / "success_traces.png").exists()
    assert "Per task" not in (tmp_path / "results.md").read_text()
    # The same records given twice would count twice: refused, naming the row and the episode.
    with pytest.raises(SystemExit):
        report.main([str(path), str(path), "--out", str(tmp_path)])


def test_results_pair_a_soft_suite_with_its_rigid_twin_on_the_shared_seeds(tmp_path):
    # The paper's rigid-twin comparison: each variant trained on each suite, paired on the seeds
    # both suites draw (evaluation.protocols.seed_key); never across variants.
    from mani_skill_softvt.evaluation.records import record_hash
    from softvt_campaign.studies import results as report

    def rec(suite, variant, seed, success):
        r = {"suite": suite, "task_id": 0, "condition": "id", "seed": seed, "success": success, "dsr_success": success,
             "r_max": 0.5, "termination": "success" if success else "timeout", "tau_o": 0.01,
             "receipt": {"policy": f"diffusion_policy[{variant}]"}, "policy": f"{variant}-{suite}.pt",
             "policy_sha256": "a" * 64, "deformation_trace": [0.0, 0.005]}
        return {**r, "record_sha256": record_hash(r)}

    rows = [rec("object_soft", "vo-c,cpu", i, i < 3) for i in range(6)]
    rows += [rec("object_rigid", "vo-c,cpu", i, i < 5) for i in range(1, 8)]  # seeds 1-5 shared with soft
    rows += [rec("object_rigid", "vt-c,cpu", i, True) for i in range(6)]
    path = tmp_path / "r.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    pairs = report.main([str(path), "--out", str(tmp_path)])["comparisons"]
    twin = pairs["id: object_soft vo-c,cpu (vo-c_cpu-object_soft) vs object_rigid vo-c,cpu (vo-c_cpu-object_rigid)"]
    # Seeds 1-5 pair: both succeed on 1, 2; only the rigid one on 3, 4; neither on 5.
    c = twin["success"]
    assert (c["pairs"], c["both"], c["only_a"], c["only_b"], c["neither"]) == (5, 2, 0, 2, 1)
    assert c["p_value"] == pytest.approx(0.5) and c["unpaired"] == 1 + 2
    assert not any("object_soft vo-c" in k and "vt-c" in k for k in pairs)
    # Beside each row, the paper's Diffusion Policy entry of that suite: a twin's TSR alone (its DSR is the TSR).
    text = (tmp_path / "results.md").read_text()
    assert "| 37.4 / 33.6 (Diffusion Policy) |" in text and "| 40.0 / = TSR (Diffusion Policy) |" in text
    assert report.paper_id_cell(report.PAPER_ID["spatial_soft"]["vt-c"]) == "33.0 / 25.0 (Diffusion Policy)"


def test_results_count_the_instance_each_spatial_row_carried_by_instructed_side(tmp_path):
    # An instruction-blind policy that always takes the left instance: every right-instructed
    # episode ends with the other instance on the target, and the side split shows it.
    from mani_skill_softvt.evaluation.metrics import DISTURBED_M
    from mani_skill_softvt.evaluation.records import record_hash
    from softvt_campaign.studies import results as report

    def rec(task, seed, side):
        success = side == "left"  # it always carried the left one
        moved = {"left": 0.2, "right": 2 * DISTURBED_M if seed == 0 else DISTURBED_M / 2}  # seed 0: both pushed
        r = {"suite": "spatial_rigid", "task_id": task, "condition": "id", "seed": seed, "success": success,
             "dsr_success": success, "r_max": 0.0, "termination": "success" if success else "timeout", "tau_o": 0.01,
             "receipt": {"policy": "diffusion_policy[vo-c,cpu]"}, "policy": "vo.pt", "policy_sha256": "a" * 64,
             "deformation_trace": [0.0, 0.0], "instructed_instance": side, "other_in_target": not success,
             "instance_displacement": moved}
        return {**r, "record_sha256": record_hash(r)}

    rows = [rec(0, s, "left") for s in range(6)] + [rec(1, s, "right") for s in range(4)]
    path = tmp_path / "r.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    report.main([str(path), "--out", str(tmp_path)])
    text = (tmp_path / "results.md").read_text()
    row = "| spatial_rigid/id/vo-c,cpu (vo) |"
    assert f"{row} all | 10 | 60.0 [" in text and text.split(f"{row} all | 10 | ")[1].split("\n")[0].endswith("| 4 | 2 |")
    assert f"{row} left | 6 | 100.0 [" in text and text.split(f"{row} left | 6 | ")[1].split("\n")[0].endswith("| 0 | 1 |")
    assert f"{row} right | 4 | 0.0 [" in text and text.split(f"{row} right | 4 | ")[1].split("\n")[0].endswith("| 4 | 1 |")
    # results.json carries the same split, for a reader that wants numbers rather than markdown
    sides = json.loads((tmp_path / "results.json").read_text())["rows"]["spatial_rigid/id/vo-c,cpu (vo)"]["by_instructed_instance"]
    assert {k: (v["episodes"], v["wrong_instance"], v["both_disturbed"]) for k, v in sides.items()} == {
        "all": (10, 4, 2), "left": (6, 0, 1), "right": (4, 4, 1)}
    assert sides["left"]["tsr"] == 1.0 and sides["right"]["tsr"] == 0.0
    # Its side swap (the same seeds, the other side instructed) carries the left one again: it succeeds
    # exactly where the ID carried the wrong instance, and the paired table says it ignored the words.
    swap = [{**r, "condition": "side_swap", "instructed_instance": {"left": "right", "right": "left"}[r["instructed_instance"]],
             "success": r["other_in_target"], "dsr_success": r["other_in_target"], "other_in_target": r["success"]}
            for r in rows]
    swap = [{**r, "record_sha256": record_hash({k: v for k, v in r.items() if k != "record_sha256"})} for r in swap]
    path.write_text("".join(json.dumps(r) + "\n" for r in rows + swap))
    swaps = report.main([str(path), "--out", str(tmp_path)])["side_swaps"]["spatial_rigid/vo-c,cpu (vo)"]
    assert (swaps["pairs"], swaps["followed"], swaps["same_instance"]) == (10, 0, 10)
    assert swaps["success"]["difference"] == pytest.approx(-0.2)  # swap TSR 40 % against ID 60 %
    assert "| spatial_rigid/vo-c,cpu (vo) | 10 | -20.0 [" in (tmp_path / "results.md").read_text()


def test_export_halves_the_weights_keeps_the_normalisers_and_never_loses_the_previous_file(tmp_path):
    from softvt_campaign.baselines import export as E
    from softvt_campaign.baselines.model import DiffusionPolicyModel

    _write_demos(tmp_path / "demos")
    cfg = make_config("vt-c", **TINY)
    source = T.train(cfg, tmp_path / "demos", tmp_path / "run", progress=False)
    dest = tmp_path / "policies" / "vt-c-tiny.pt"
    assert E.export(source, dest)
    full, half = torch.load(source, weights_only=False), torch.load(dest, weights_only=False)
    assert half["exported_from"] == __import__("hashlib").sha256(source.read_bytes()).hexdigest()
    for k, v in half["model"].items():
        if k.startswith("normalize."):
            assert v.dtype == torch.float32 and torch.equal(v, full["model"][k])
        elif v.is_floating_point():
            # float16 keeps 11 significant bits: each weight within 2^-11 of itself, relatively.
            assert v.dtype == torch.float16
            assert torch.allclose(v.float(), full["model"][k], rtol=2 ** -11, atol=6e-8)
    _, model, _ = load_policy_file(dest)  # loads as float32 weights
    assert all(p.dtype == torch.float32 for p in model.parameters())
    # Unchanged source: nothing written with --if-changed; too large: refused, the previous file kept.
    mtime = dest.stat().st_mtime_ns
    assert not E.export(source, dest, if_changed=True) and dest.stat().st_mtime_ns == mtime
    with pytest.raises(ValueError, match="MiB.*left as it was"):
        E.export(source, dest, max_mib=1e-4)
    assert dest.stat().st_mtime_ns == mtime and torch.load(dest, weights_only=False)["exported_from"]
    # The cpu preset's VO and VT networks fit in a committed policy's 20 MiB in float16.
    import io

    for variant in ("vo-c", "vt-c"):
        preset = make_config(variant)
        buf = io.BytesIO()
        torch.save(E.half_state(DiffusionPolicyModel(preset, T.empty_stats(preset)).state_dict()), buf)
        assert buf.tell() / 2 ** 20 < E.MAX_MIB, (variant, buf.tell() / 2 ** 20)


def test_train_command_line_applies_recipes_to_the_cpu_preset_only(tmp_path):
    with pytest.raises(SystemExit):
        T.main(["--variant", "vo-c", "--config", "paper", "--recipe", "long", "--demos", str(tmp_path)])
    assert T.default_out(make_config("vo-c"), "long").name == "vo-c-cpu-long"
    assert T.default_out(make_config("vo-c", "paper"), None).name == "vo-c-paper"


def test_the_train_command_takes_float32_products_pinned_in_full_where_the_cpu_has_no_bfloat16(tmp_path, monkeypatch,
                                                                                               capsys):
    from softvt_campaign.baselines import bf16

    _write_demos(tmp_path / "demos")
    monkeypatch.setattr(bf16, "cpu_flags", lambda: {"avx2", "fma"})  # an AVX2-only CPU: auto takes float32
    sets = [f"{k}={','.join(map(str, v)) if isinstance(v, tuple) else v}" for k, v in TINY.items()]
    path = T.main(["--variant", "vo-c", "--set", *sets, "--demos", str(tmp_path / "demos"), "--out", str(tmp_path / "run")])
    policy = torch.load(path, weights_only=False)
    assert policy["bf16_product_steps"] == {"float32": TINY["steps"]}
    assert policy["numerics"]["pinned"] and not policy["numerics"]["released"]  # nothing released
    assert "float32 kernels" in capsys.readouterr().out


def test_inference_fields_do_not_change_training(tmp_path):
    # What the recipe search relies on to derive exec4 from long without training it again.
    from softvt_campaign.baselines.config import INFERENCE_FIELDS, training_identity

    _write_demos(tmp_path / "demos")
    cfg = make_config("vo-c", **TINY)
    other = make_config("vo-c", **{**TINY, "action_steps": 4, "inference_timesteps": 2, "inference_scheduler": "ddpm"})
    assert set(INFERENCE_FIELDS) == {"action_steps", "inference_timesteps", "inference_scheduler"}
    assert training_identity(cfg) == training_identity(other) != training_identity(make_config("vo-c", **{**TINY, "lr": 1}))
    a = torch.load(T.train(cfg, tmp_path / "demos", tmp_path / "a", progress=False), weights_only=False)
    b = torch.load(T.train(other, tmp_path / "demos", tmp_path / "b", progress=False), weights_only=False)
    assert all(torch.equal(a["model"][k], b["model"][k]) for k in a["model"])


def test_closure_summary_tells_one_held_closure_from_a_ratchet():
    from softvt_campaign.studies.closure import closure_summary, held_chunks

    k = 8
    # The expert: one closure for the whole hold. The object is held from the closing chunk's
    # third step on, so that chunk is not a held one.
    expert = [0.0] * 10 + [0.6] * 46 + [0.0] * 8
    expert_held = [False] * 18 + [True] * 38 + [False] * 8
    assert held_chunks(expert, expert_held, k).tolist() == [0.6] * 4
    s = closure_summary(expert, expert_held, k)
    assert (s["held_chunks"], s["first"], s["last"], s["rise"], s["max"]) == (4, 0.6, 0.6, 0.0, 0.6)
    # A policy's closure rising chunk by chunk; its release chunk (half closed) and the open steps
    # after it, whose closure is irrelevant, do not count; nor does a spike while not holding.
    ratchet = [0.95] * 8 + [v for v in (0.45, 0.55, 0.7, 0.85, 0.9) for _ in range(k)] + [0.9] * 4 + [0.0] * 9
    held = [False] * 8 + [True] * 44 + [False] * 9
    s = closure_summary(ratchet, held, k)
    assert s["first"] == 0.45 and s["last"] == 0.9 and s["rise"] == pytest.approx(0.45) and s["max"] == 0.9
    # The episode's last chunk may be short (the episode ends mid-chunk) and still held.
    s = closure_summary([0.5] * 8 + [0.7] * 3, [True] * 11, k)
    assert (s["held_chunks"], s["last"]) == (2, 0.7)
    assert closure_summary([0.0] * 16, [False] * 16, k)["first"] is None  # never held: nothing to summarise
    with pytest.raises(ValueError, match="differ in length"):
        held_chunks([0.5] * 8, [True] * 7, k)


def test_closure_summary_names_the_closure_that_let_the_object_go():
    from softvt_campaign.studies.closure import closure_summary

    k = 8
    # Held over three chunks at 0.6, 0.8 and 0.6 (a policy switching between demos' closures), then
    # a chunk that opens the fingers (0.45, then lower): the spread is that of the held chunks,
    # let_go the first closure after the last held step, not a later one.
    closure = [0.0] * 8 + [0.6] * 8 + [0.8] * 8 + [0.6] * 8 + [0.45, 0.3, 0.2, 0.1, 0.0, 0.0, 0.0, 0.0]
    held = [False] * 8 + [True] * 24 + [False] * 8
    s = closure_summary(closure, held, k)
    assert s["spread"] == pytest.approx(np.std([0.6, 0.8, 0.6])) and s["let_go"] == 0.45
    # The pads: 6 N through the hold (5.5 N at its last step), 0 once the fingers open (no slip under load).
    grip = [0.0] * 8 + [6.0] * 23 + [5.5] + [0.0, 1.0, 2.0] + [0.0] * 5
    s = closure_summary(closure, held, k, grip)
    assert (s["grip_held"], s["grip_let_go"]) == (5.5, 0.0)
    with pytest.raises(ValueError, match="differ in length"):
        closure_summary(closure, held, k, grip[:-1])
    # Held to the end: nothing let go. One closure over several chunks, as the expert: no spread.
    s = closure_summary([0.6] * 16, [True] * 16, k, [4.0] * 16)
    assert s["let_go"] is None and s["grip_let_go"] is None and s["grip_held"] == 4.0 and s["spread"] == 0.0
    assert closure_summary([0.6] * 8, [True] * 8, k)["spread"] is None  # one held chunk shows no switching
    never = closure_summary([0.0] * 16, [False] * 16, k, [0.0] * 16)
    assert never["let_go"] is None and never["grip_held"] is None and never["spread"] is None


def test_closure_study_judges_records_as_evaluate_reproduce_and_names_the_stack():
    from softvt_campaign.studies.closure import record_check

    here = {"cpu": "Intel Xeon", "torch": "2.11.0"}
    assert record_check({1: [], 2: []}, [here, here], here)["records_failed"] is False
    c = record_check({1: ["r_max", "steps"], 2: []}, [here, here], here)
    assert c["records_failed"] and c["records_stack_differences"] == [] and c["records_outcome_differing"] == []
    # Another machine: the same episode keeps its outcome, not its bits. The bits still fail the
    # check (as evaluate --reproduce); the stack says why, and the outcomes are compared.
    epyc = {"cpu": "AMD EPYC", "torch": "2.11.0"}
    c = record_check({1: ["r_max"], 2: ["termination", "success"]}, [epyc, here], here)
    assert c["records_failed"] and c["records_stack_differences"] == ["cpu AMD EPYC -> Intel Xeon"]
    assert c["records_outcome_differing"] == [2]
    c = record_check({1: ["r_max"]}, [None], here)
    assert c["records_failed"] and c["records_stack_differences"] == "unrecorded"


def test_closure_readout_tells_a_squeezable_object_from_a_rigid_one():
    from softvt_campaign.studies.closure import closure_readout

    c = np.linspace(0.3, 0.9, 20)
    # Soft: the fingers go 18 mm further in over the closure range, and the pads press harder.
    soft = closure_readout(c, 0.060 - 0.030 * (c - 0.3), 10.0 * c)
    assert soft["corr"] == pytest.approx(-1.0) and soft["slope_mm"] == pytest.approx(-30.0)
    assert soft["width_range_mm"] == pytest.approx([42.0, 60.0]) and soft["grip_corr"] == pytest.approx(1.0)
    # Rigid: the jaw stops at the object's width whatever the closure, up to PhysX's 0.1 mm jitter.
    jitter = np.random.default_rng(0).normal(0, 1e-4, c.size)
    rigid = closure_readout(c, 0.060 + jitter)
    assert abs(rigid["slope_mm"]) < 0.5 and np.ptp(rigid["width_range_mm"]) < 1.0
    assert closure_readout(c, np.full(c.size, 0.06))["corr"] == 0.0  # a width that never moves reads nothing
    with pytest.raises(ValueError, match="same closure"):
        closure_readout(np.full(5, 0.5), np.linspace(0.05, 0.06, 5))
    with pytest.raises(ValueError, match="at least 3"):
        closure_readout([0.3, 0.9], [0.06, 0.05])
    with pytest.raises(ValueError, match="one held force per demo"):
        closure_readout(c, 0.060 + jitter, [1.0, 2.0])


def test_demo_closures_reads_each_demos_held_closure_and_width(tmp_path):
    from softvt_campaign.studies.closure import demo_closures

    ds = DemoSet(tmp_path, "object_rigid")
    ds.dir.mkdir(parents=True)
    with h5py.File(ds.trajectory(2), "w") as ft:
        for e, (closure, width) in enumerate([(0.5, 0.034), (0.7, 0.0341), (0.9, 0.0339)]):
            g = ft.create_group(f"traj_{e}")
            g.attrs["closure"] = closure  # the expert's draw
            g["evaluator/is_grasped"] = np.array([0, 0, 1, 1, 0, 0], bool)  # held after steps 2 and 3
            # Row t + 1 is the state after step t: the held rows are 3 and 4. Every other row differs,
            # so reading the rows one off (or the reset's) gives another median.
            state = np.zeros((7, 13 + 9 + 9), np.float32)  # root pose, velocity, qpos (9), qvel (9)
            state[:, 20:22] = (np.array([0.08, 0.07, 0.05, width, width + 2e-4, 0.06, 0.08]) / 2)[:, None]
            g["env_states/articulations/panda_softvt"] = state
            g["evaluator/pad_force"] = np.array([[0, 0], [0, 9], [5, 4], [3, 2 + e], [8, 7], [0, 0]], np.float32)
        ft["traj_3/evaluator/is_grasped"] = np.zeros(3, bool)  # never held: not a demo of a closure
    closures, widths, grips = demo_closures(ds, 2)
    assert closures.tolist() == pytest.approx([0.5, 0.7, 0.9])
    assert widths.tolist() == pytest.approx([0.0341, 0.0342, 0.0340])  # the median of the two held rows
    assert grips.tolist() == pytest.approx([3.0, 3.5, 3.5])  # the weaker pad over steps 2 and 3
    with pytest.raises(FileNotFoundError, match="generate"):
        demo_closures(ds, 3)
    with h5py.File(ds.trajectory(2), "a") as ft:
        del ft["traj_0"].attrs["closure"]
    with pytest.raises(ValueError, match="no 'closure' attribute"):
        demo_closures(ds, 2)


@pytest.mark.parametrize("args, message", [
    (["nowhere.pt"], "not a policy file"),
    (["{policy}", "--task", "10"], "--task must be in"),
    (["{policy}", "--episodes", "0"], "--episodes must be in"),
    (["{policy}", "--episodes", "51"], "--episodes must be in"),
    (["{committed}", "{committed}"], "two policies are named"),
])
def test_closure_refuses_bad_input_before_running_anything(tmp_path, capsys, args, message):
    from softvt_campaign.studies import closure

    policy = tmp_path / "p.pt"
    policy.write_bytes(b"")  # never read: the range checks come before the policy file is needed
    committed = Path(__file__).resolve().parents[1] / "campaign-data" / "policies" / "vo-c-cpu.pt"
    argv = [a.format(policy=policy, committed=committed) for a in args]
    with pytest.raises(SystemExit):
        closure.main(argv)
    assert message in capsys.readouterr().err
