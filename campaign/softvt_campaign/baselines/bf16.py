"""bfloat16 products through float32 kernels: the cpu preset's mixed precision on a CPU without
bfloat16 instructions.

Under ``torch.autocast(dtype=torch.bfloat16)`` (``precision="bf16"``) a convolution or matrix
product takes bfloat16 operands and returns a bfloat16 result. On a CPU with AVX-512 BF16 or AMX,
where the committed policies trained, oneDNN multiplies the operands exactly, accumulates in
float32 (its default, "strict" accumulation mode: oneDNN Developer Guide, "Primitive Attributes:
accumulation mode") and rounds the result once to bfloat16. A CPU without those instructions has
no such kernel: its emulation costs 14x a float32 step on an AVX2-only AMD EPYC, and its
convolution gradients there round more than once (measured: docs/benchmarks.md).

:class:`Float32Products` computes the same thing with float32 kernels. A bfloat16 operand widens
to float32 exactly, the product of two bfloat16 significands (8 bits each) is exact in float32's
24, the sums accumulate in float32 and the result is rounded once to bfloat16: the semantics of
the bfloat16 kernels, apart from the order of the float32 sums (which differs between any two
kernels anyway: AMX against AVX-512 BF16, one thread against two) and denormal products, which the
bfloat16 dot-product instructions flush to zero. Everything else autocast runs in bfloat16 (the
activations, the normalisations' inputs) stays as it is; a training under it keeps its encoders
NCHW, so those ops run their NCHW kernels (other summation orders again). Only training uses it
(``softvt-train --bf16-products``); a policy samples with the native kernels, as every committed
policy's evaluations did.

Written here because no library offers it: torch's and oneDNN's precision switches
(``torch.set_float32_matmul_precision``, oneDNN's fpmath mode) go the other way, float32
products computed in bfloat16.
"""

from __future__ import annotations

import torch
from torch.utils._python_dispatch import TorchDispatchMode

from mani_skill_softvt.provenance.numerics import cpu_flags

# What ``--bf16-products`` accepts; "auto" picks native where the CPU has bfloat16 instructions.
BF16_PRODUCTS = ("auto", "native", "float32")
BF16_INSTRUCTIONS = ("avx512_bf16", "amx_bf16")

_aten = torch.ops.aten
# The operators autocast's bfloat16 products reach below autograd (conv1d/2d, transposed ones and
# linear decompose into these), forward and backward; tests/test_baselines.py checks that a training
# step of each variant reaches no other product.
MATRIX_PRODUCTS = frozenset({_aten.mm.default, _aten.addmm.default, _aten.bmm.default, _aten.baddbmm.default})
PRODUCTS = MATRIX_PRODUCTS | {_aten.convolution.default, _aten.convolution_backward.default}


def has_bf16_instructions(flags: set[str] | None = None) -> bool:
    """Whether the CPU (``/proc/cpuinfo``'s flags, or ``flags``) has bfloat16 dot-product instructions."""
    return bool(set(BF16_INSTRUCTIONS) & (cpu_flags() if flags is None else set(flags)))


def choose_products(choice: str, precision: str, flags: set[str] | None = None) -> str | None:
    """The products a training of ``precision`` runs with: ``None`` for float32 training, else
    ``"native"`` or ``"float32"``; ``"auto"`` takes native only where the CPU has bfloat16
    instructions (elsewhere native costs about 12x a step for the same arithmetic)."""
    if choice not in BF16_PRODUCTS:
        raise ValueError(f"--bf16-products {choice!r}: choose one of {BF16_PRODUCTS}")
    if precision != "bf16":
        return None
    if choice == "auto":
        return "native" if has_bf16_instructions(flags) else "float32"
    return choice


def _widen(x, nchw: bool = False):
    if not (isinstance(x, torch.Tensor) and x.dtype == torch.bfloat16):
        return x
    return x.to(torch.float32, memory_format=torch.contiguous_format) if nchw else x.float()


def _channels_last(t: torch.Tensor) -> bool:
    return t.dim() == 4 and t.is_contiguous(memory_format=torch.channels_last) and not t.is_contiguous()


def _round(x, *like: torch.Tensor):
    """``x`` rounded to bfloat16, channels-last where any of ``like`` is (as torch's convolutions choose)."""
    if not isinstance(x, torch.Tensor):
        return x
    x = x.to(torch.bfloat16)
    return x.contiguous(memory_format=torch.channels_last) if any(map(_channels_last, like)) else x


class Float32Products(TorchDispatchMode):
    """Within it, each bfloat16 convolution or matrix product (and its gradients) runs as float32
    kernels on the widened operands, its results rounded once to bfloat16. ``calls`` counts them."""

    def __init__(self):
        super().__init__()
        self.calls = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        if func not in PRODUCTS or not any(isinstance(a, torch.Tensor) and a.dtype == torch.bfloat16 for a in args):
            return func(*args, **kwargs)
        self.calls += 1
        if func in MATRIX_PRODUCTS:
            return _round(func(*map(_widen, args), **{k: _widen(v) for k, v in kwargs.items()}))
        # Convolutions compute in float32 on NCHW operands (a training under this mode keeps its
        # encoders NCHW: no copies) and hand back the layouts they were given. torch 2.13's float32
        # channels-last backward of a strided 1x1 convolution over 4 channels corrupts the heap (a
        # tiny encoder's shortcut); its NCHW and bfloat16 kernels do not.
        out = func(*(_widen(a, nchw=True) for a in args), **kwargs)
        if func is _aten.convolution.default:
            return _round(out, args[0], args[1])
        grad_input, grad_weight, grad_bias = out
        return _round(grad_input, args[1], args[2]), _round(grad_weight, args[1], args[2]), _round(grad_bias)
