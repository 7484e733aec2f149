"""The stack a record names: what explains a reproduction that keeps its outcome but not its bits."""

from __future__ import annotations

import torch

from mani_skill_softvt.stack import ARITHMETIC_CPU_FLAGS, cpu_isa, software_stack, stack_differences, unrecorded


def test_cpu_isa_names_the_features_that_choose_the_arithmetic():
    # Two machines a VM names alike ("Intel(R) Xeon(R) Processor"): with and without AMX tiles,
    # which oneDNN uses for the policies' bfloat16 products (other rounding than AVX-512 BF16).
    amx = cpu_isa({"fpu", "avx2", "fma", "avx512f", "avx512_bf16", "amx_bf16", "amx_tile"}, "AVX512", "")
    no_amx = cpu_isa({"fpu", "avx2", "fma", "avx512f", "avx512_bf16"}, "AVX512", "")
    assert amx == "AVX512 amx_bf16 avx512_bf16 avx512f avx2 fma"
    assert no_amx == "AVX512 avx512_bf16 avx512f avx2 fma"
    assert cpu_isa({"avx2", "fma"}, "AVX2", "AVX2") == "AVX2 avx2 fma onednn_max=AVX2"  # a cap is named
    old, new = {"cpu": "Intel(R) Xeon(R) Processor", "cpu-isa": no_amx}, {"cpu": "Intel(R) Xeon(R) Processor", "cpu-isa": amx}
    assert stack_differences(old, new) == [f"cpu-isa {no_amx} -> {amx}"]
    # A record from before the ISA was named says it is unknown, neither the same nor different.
    assert stack_differences({"cpu": "Intel(R) Xeon(R) Processor"}, new) == ["cpu-isa unrecorded"]
    assert unrecorded(["cpu-isa unrecorded", "torch 2.13.0 -> 2.11.0"]) == ["cpu-isa"]
    assert cpu_isa(set(), "NO AVX", "").split() == ["NO_AVX"]  # one word per part, whatever torch names


def test_this_machines_stack_names_its_cpu_isa():
    isa = software_stack()["cpu-isa"]
    assert isa.split()[0] == torch.backends.cpu.get_cpu_capability()
    assert set(isa.split()[1:]) <= set(ARITHMETIC_CPU_FLAGS) | {w for w in isa.split() if w.startswith("onednn_max=")}
