"""The networks of the Diffusion Policy baselines: image encoders and the conditional 1-D U-Net.

Written here because torchvision (whose ResNet-18 Diffusion Policy uses) does not load with the
CPU torch of the pinned stack, and the U-Net is Diffusion Policy's design, not a library class.

- :class:`ImageEncoder`: a ResNet (basic blocks, GroupNorm in place of BatchNorm as Diffusion
  Policy does, since batch statistics and EMA weights do not mix), ending in a spatial softmax
  (expected keypoint coordinates, robomimic's pooling) and a linear layer. ResNet-18 is
  ``widths=(64, 128, 256, 512), blocks=(2, 2, 2, 2)``.
- :class:`ConditionalUnet1D`: a temporal U-Net over the action chunk; every residual block is
  FiLM-modulated by the diffusion step embedding concatenated with the observation features.
"""

from __future__ import annotations

import math

import torch
from torch import nn
from torch.nn import functional as F

from mani_skill_softvt.provenance.numerics import chosen as chosen_numerics


def _groups(channels: int) -> int:
    return max(1, channels // 16)


class BasicBlock(nn.Module):
    def __init__(self, cin: int, cout: int, stride: int):
        super().__init__()
        self.conv1 = nn.Conv2d(cin, cout, 3, stride, 1, bias=False)
        self.norm1 = nn.GroupNorm(_groups(cout), cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, 1, 1, bias=False)
        self.norm2 = nn.GroupNorm(_groups(cout), cout)
        self.skip = (nn.Identity() if stride == 1 and cin == cout else
                     nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.GroupNorm(_groups(cout), cout)))

    def forward(self, x):
        y = F.relu(self.norm1(self.conv1(x)))
        return F.relu(self.norm2(self.conv2(y)) + self.skip(x))


class SpatialSoftmax(nn.Module):
    """Per channel, the softmax-weighted mean image coordinate in [-1, 1]: (B, C, H, W) -> (B, 2C).
    Always in float32: a bfloat16 mean over thousands of pixels would move a keypoint by whole
    pixels."""

    def forward(self, x):
        with torch.autocast(device_type=x.device.type, enabled=False):
            return self._keypoints(x.float())

    @staticmethod
    def _keypoints(x):
        b, c, h, w = x.shape
        weights = torch.softmax(x.reshape(b, c, h * w), dim=-1)
        ys = torch.linspace(-1.0, 1.0, h, device=x.device).repeat_interleave(w)
        xs = torch.linspace(-1.0, 1.0, w, device=x.device).repeat(h)
        if "keypoints" in chosen_numerics().parts:
            # ATen's reduction sums in the same order on any CPU; a product with a vector is MKL's GEMV,
            # whose AMD path ignores MKL's reproducibility mode (provenance/numerics.py, the keypoints part).
            return torch.cat([(weights * xs).sum(-1), (weights * ys).sum(-1)], dim=-1)
        return torch.cat([weights @ xs, weights @ ys], dim=-1)  # the earlier pins' products, for their records


class ImageEncoder(nn.Module):
    """(B, C, H, W) float image in [-1, 1] -> (B, feature_dim). With ``channels_last`` the
    convolutions run on NHWC tensors (weights and activations), which oneDNN's CPU kernels take
    without reordering: the same numbers up to summation order, a fifth less time per step."""

    def __init__(self, in_channels: int, widths: tuple[int, ...], blocks: tuple[int, ...], feature_dim: int,
                 keypoints: int = 32, resnet_stem: bool = False, channels_last: bool = False):
        super().__init__()
        # ResNet-18's stem divides the image by 4 (fine at 224 px); small images keep more pixels.
        conv = (nn.Conv2d(in_channels, widths[0], 7, 2, 3, bias=False) if resnet_stem else
                nn.Conv2d(in_channels, widths[0], 3, 2, 1, bias=False))
        self.stem = nn.Sequential(conv, nn.GroupNorm(_groups(widths[0]), widths[0]), nn.ReLU(),
                                  *([nn.MaxPool2d(3, 2, 1)] if resnet_stem else []))
        layers, cin = [], widths[0]
        for i, (w, n) in enumerate(zip(widths, blocks)):
            for j in range(n):
                layers.append(BasicBlock(cin, w, 2 if (j == 0 and i > 0) else 1))
                cin = w
        self.stages = nn.Sequential(*layers)
        self.keypoints = nn.Conv2d(cin, keypoints, 1)
        self.pool = SpatialSoftmax()
        self.out = nn.Linear(2 * keypoints, feature_dim)
        self.use_channels_last(channels_last)

    def use_channels_last(self, on: bool) -> None:
        """Switch weights and inputs between NHWC and NCHW (the same values, another layout)."""
        self.channels_last = on
        self.to(memory_format=torch.channels_last if on else torch.contiguous_format)

    def forward(self, x):
        if self.channels_last:
            x = x.contiguous(memory_format=torch.channels_last)
        return self.out(self.pool(self.keypoints(self.stages(self.stem(x)))))


def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal embedding of diffusion steps ``t`` (B,) -> (B, dim), periods up to 10^4 steps."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, dtype=torch.float32, device=t.device) / max(half - 1, 1))
    args = t.float()[:, None] * freqs[None]
    return torch.cat([args.sin(), args.cos()], dim=-1)


class ConvBlock1D(nn.Sequential):
    def __init__(self, cin: int, cout: int, kernel: int, groups: int):
        super().__init__(nn.Conv1d(cin, cout, kernel, padding=kernel // 2), nn.GroupNorm(groups, cout), nn.Mish())


class FiLMResBlock1D(nn.Module):
    """Two conv blocks; the first one's output is scaled and shifted by the conditioning (FiLM)."""

    def __init__(self, cin: int, cout: int, cond_dim: int, kernel: int, groups: int):
        super().__init__()
        self.block1 = ConvBlock1D(cin, cout, kernel, groups)
        self.block2 = ConvBlock1D(cout, cout, kernel, groups)
        self.film = nn.Sequential(nn.Mish(), nn.Linear(cond_dim, 2 * cout))
        self.skip = nn.Conv1d(cin, cout, 1) if cin != cout else nn.Identity()

    def forward(self, x, cond):
        scale, shift = self.film(cond)[..., None].chunk(2, dim=1)
        y = self.block1(x) * scale + shift
        return self.block2(y) + self.skip(x)


class ConditionalUnet1D(nn.Module):
    """Noise prediction over an action chunk: (B, T, A) noisy actions, (B,) steps, (B, G) observation
    features -> (B, T, A). ``T`` must be divisible by 2^(len(dims) - 1)."""

    def __init__(self, action_dim: int, global_cond_dim: int, dims: tuple[int, ...], kernel: int = 5,
                 groups: int = 8, step_embed_dim: int = 128):
        super().__init__()
        self.step_embed_dim = step_embed_dim
        self.step_mlp = nn.Sequential(nn.Linear(step_embed_dim, 4 * step_embed_dim), nn.Mish(),
                                      nn.Linear(4 * step_embed_dim, step_embed_dim))
        cond = step_embed_dim + global_cond_dim
        chans = [action_dim, *dims]
        self.down = nn.ModuleList()
        for i, (cin, cout) in enumerate(zip(chans[:-1], chans[1:])):
            last = i == len(dims) - 1
            self.down.append(nn.ModuleList([FiLMResBlock1D(cin, cout, cond, kernel, groups),
                                            FiLMResBlock1D(cout, cout, cond, kernel, groups),
                                            nn.Identity() if last else nn.Conv1d(cout, cout, 3, 2, 1)]))
        self.mid = nn.ModuleList([FiLMResBlock1D(dims[-1], dims[-1], cond, kernel, groups) for _ in range(2)])
        self.up = nn.ModuleList()
        for cout, cin in reversed(list(zip(dims[:-1], dims[1:]))):
            self.up.append(nn.ModuleList([FiLMResBlock1D(2 * cin, cout, cond, kernel, groups),
                                          FiLMResBlock1D(cout, cout, cond, kernel, groups),
                                          nn.ConvTranspose1d(cout, cout, 4, 2, 1)]))
        self.final = nn.Sequential(ConvBlock1D(dims[0], dims[0], kernel, groups), nn.Conv1d(dims[0], action_dim, 1))
        self.min_length = 2 ** (len(dims) - 1)

    def forward(self, sample: torch.Tensor, step: torch.Tensor, global_cond: torch.Tensor) -> torch.Tensor:
        if sample.shape[1] % self.min_length:
            raise ValueError(f"action horizon {sample.shape[1]} must be divisible by {self.min_length}")
        cond = torch.cat([self.step_mlp(timestep_embedding(step, self.step_embed_dim)), global_cond], dim=-1)
        x = sample.transpose(1, 2)  # (B, A, T): convolve over time
        skips = []
        for res1, res2, down in self.down:
            x = res2(res1(x, cond), cond)
            skips.append(x)
            x = down(x)
        for res in self.mid:
            x = res(x, cond)
        for res1, res2, up in self.up:
            x = torch.cat([x, skips.pop()], dim=1)
            x = up(res2(res1(x, cond), cond))
        return self.final(x).transpose(1, 2)
