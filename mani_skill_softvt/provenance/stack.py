"""The software stack a result was made on, named in every evaluation record.

The same episode on another stack (another torch, NumPy, Warp, Newton or SAPIEN, another Python)
keeps its outcome but not its bits; a record that names its stack lets ``evaluate --reproduce``
say why a reproduction differs instead of leaving it unexplained.
"""

from __future__ import annotations

import os
import platform
from functools import lru_cache
from importlib import metadata

import cv2
import torch

from .numerics import chosen, cpu_flags, resolved
from ..version import __version__

# The distributions whose arithmetic reaches a record: the physics (warp, newton, sapien), the
# policy's network and sampler (torch, diffusers), the array maths (numpy) and ManiSkill's env glue.
STACK_DISTRIBUTIONS = ("torch", "numpy", "warp-lang", "newton", "sapien", "mani-skill", "diffusers")


def cpu_model(cpuinfo: str | None = None) -> str:
    """The processor's model name: machines of one kind can differ in it (an AMD EPYC and an Intel
    Xeon round the same episode differently, and a learned policy's closed loop amplifies that).
    ``cpuinfo``: the text of /proc/cpuinfo (None: read this machine's)."""
    if cpuinfo is None:
        try:
            with open("/proc/cpuinfo") as fh:
                cpuinfo = fh.read()
        except OSError:
            cpuinfo = ""
    arm: dict[str, str] = {}
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        key = key.strip()
        if key == "model name":
            return value.strip()
        if key in ("CPU implementer", "CPU part"):  # ARM kernels name no model: these identify the core
            arm.setdefault(key, value.strip())
    if len(arm) == 2:
        return f"{platform.machine()} implementer {arm['CPU implementer']} part {arm['CPU part']}"
    return platform.processor() or platform.machine()


# CPU features that choose a kernel's arithmetic, not only its speed. oneDNN runs the policies'
# bfloat16 products on AMX tiles where the CPU has them, else with AVX-512 BF16 instructions, else
# emulated, and each rounds differently (measured: the same denoised chunk differs in its fourth
# digit); NumPy and OpenBLAS pick AVX-512 or AVX2 kernels at run time. A virtual machine may name
# every Intel CPU "Intel(R) Xeon(R) Processor", so the model name alone cannot tell them apart.
# On ARM (``Features`` in /proc/cpuinfo) the same choice is between SVE/SVE2 and NEON (asimd)
# kernels, and bfloat16 products with the BF16 and I8MM extensions or emulated.
ARITHMETIC_CPU_FLAGS = ("amx_bf16", "avx512_bf16", "avx512f", "avx2", "fma",  # x86
                        "sve2", "sve", "bf16", "i8mm", "asimd")  # arm


def cpu_isa(flags: set[str] | None = None, torch_capability: str | None = None,
            onednn_max_isa: str | None = None) -> str:
    """``"AVX512 amx_bf16 avx512_bf16 avx512f avx2 fma"``: torch's vector capability, then those of
    :data:`ARITHMETIC_CPU_FLAGS` the CPU has, then oneDNN's ISA cap if ``ONEDNN_MAX_CPU_ISA`` sets one.
    Arguments left None are read from this machine."""
    if flags is None:
        flags = cpu_flags()
    if torch_capability is None:
        torch_capability = torch.backends.cpu.get_cpu_capability()
    if onednn_max_isa is None:
        onednn_max_isa = os.environ.get("ONEDNN_MAX_CPU_ISA") or os.environ.get("DNNL_MAX_CPU_ISA") or ""
    parts = [torch_capability.replace(" ", "_")] + [f for f in ARITHMETIC_CPU_FLAGS if f in flags]
    return " ".join(parts + ([f"onednn_max={onednn_max_isa}"] if onednn_max_isa else []))


@lru_cache(maxsize=1)
def _stack() -> tuple[tuple[str, str | None], ...]:
    out = {"python": platform.python_version(), "mani-skill-softvt": __version__, "opencv": cv2.__version__,
           "cpu": cpu_model(), "cpu-isa": cpu_isa()}
    for dist in STACK_DISTRIBUTIONS:
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = None
    out["torch"] = torch.__version__
    return tuple(out.items())


MACHINE_KEYS = ("cpu", "cpu-isa")  # what names the machine's kind; under pinned numerics it does not choose the bits


def software_stack() -> dict[str, str | None]:
    """``{"python": ..., "mani-skill-softvt": ..., "torch": ..., "opencv": ..., ...}`` of this process
    (a new dict each call: records do not share one)."""
    return dict(_stack())


def stack_differences(recorded: dict | None, current: dict) -> list[str]:
    """``["torch 2.13.0 -> 2.11.0", "cpu-isa unrecorded", ...]``: what differs between a recorded stack
    and this one (empty when they are the same or the record predates stacks being recorded). A key
    the record lacks, named only since it was made, reads ``"<key> unrecorded"``: unknown, not different."""
    if not recorded:
        return []
    return [f"{k} unrecorded" if k not in recorded else f"{k} {recorded.get(k)} -> {current.get(k)}"
            for k in sorted(set(recorded) | set(current)) if recorded.get(k) != current.get(k)]


def unrecorded(differences: list[str]) -> list[str]:
    """The keys of :func:`stack_differences` that the record lacks (the rest are real mismatches)."""
    return [d.removesuffix(" unrecorded") for d in differences if d.endswith(" unrecorded")]


def main(argv=None) -> None:
    """``python -m mani_skill_softvt.provenance.stack``: the stack and the numerics a record made here would name.
    ``--export`` prints the pinning variables as shell exports instead, for a process that loads NumPy
    or torch before this package (the LeRobot stack's ``lerobot-eval``):
    ``eval "$(python -m mani_skill_softvt.provenance.stack --export)"`` pins it in full."""
    import argparse
    import json
    import shlex

    ap = argparse.ArgumentParser(description="the stack and numerics a record made here would name")
    ap.add_argument("--export", action="store_true", help="print the pinning variables as shell exports")
    args = ap.parse_args(argv)
    if args.export:
        for var, value in sorted(chosen().environment().items()):
            print(f"export {var}={shlex.quote(value)}")
        return
    print(json.dumps({"stack": software_stack(), "numerics": resolved()}, indent=1))


if __name__ == "__main__":
    main()
