"""The stack a record names: what explains a reproduction that keeps its outcome but not its bits."""

from __future__ import annotations

import torch

from mani_skill_softvt.provenance.stack import ARITHMETIC_CPU_FLAGS, cpu_isa, cpu_model, software_stack, stack_differences, unrecorded


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


def test_arm_machines_are_told_apart_by_their_vector_extensions_and_core():
    # /proc/cpuinfo of a Neoverse V1 (SVE, BF16) and a Neoverse N1 (NEON only), shortened: oneDNN
    # takes other bfloat16 kernels on each, and neither kernel names a model.
    v1 = "fp asimd aes sha2 crc32 atomics fphp asimdhp asimddp sve svebf16 i8mm bf16 rng"
    n1 = "fp asimd aes sha2 crc32 atomics fphp asimdhp asimddp ssbs"
    assert cpu_isa(set(v1.split()), "SVE256", "") == "SVE256 sve bf16 i8mm asimd"
    assert cpu_isa(set(n1.split()), "DEFAULT", "") == "DEFAULT asimd"
    info = f"processor\t: 0\nBogoMIPS\t: 2100.00\nFeatures\t: {v1}\nCPU implementer\t: 0x41\nCPU part\t: 0xd40\n"
    assert cpu_model(info).endswith("implementer 0x41 part 0xd40")
    assert cpu_model("processor\t: 0\nmodel name\t: AMD EPYC 9R14\n") == "AMD EPYC 9R14"


def test_this_machines_stack_names_its_cpu_isa():
    isa = software_stack()["cpu-isa"]
    assert isa.split()[0] == torch.backends.cpu.get_cpu_capability()
    assert set(isa.split()[1:]) <= set(ARITHMETIC_CPU_FLAGS) | {w for w in isa.split() if w.startswith("onednn_max=")}
