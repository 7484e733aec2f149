"""Numerics that do not depend on the machine: every CPU dispatch of the stack pinned to one target.

The libraries under the benchmark choose their machine code by the CPU they find: Warp compiles
Newton's kernels with ``-march=native``; torch's ATen, oneDNN and MKL, NumPy's OpenBLAS and its own
loops, OpenCV and Mesa's llvmpipe (which renders the cameras) each pick AVX-512 kernels where the
CPU has them. Kernels for other instruction sets round differently, and a closed loop turns one
rounding into another episode: a VO-C record made on an AMD EPYC replayed on an Intel Xeon matched
0 of 10 episodes bit for bit (docs/install.md). So every dispatch is pinned here, in one place, to
``x86-64-v3`` (AVX2 + FMA, which every x86-64 machine of the last decade has), before the
libraries load:

- the package's import calls :func:`pin` first thing (``mani_skill_softvt/__init__.py``), so a
  command (``python -m mani_skill_softvt...``), and every worker process it spawns, is pinned;
- Ray workers get the same variables through their ``runtime_env`` (:func:`environment`), set
  before Ray itself loads NumPy there;
- a process that loaded NumPy or torch before importing this package, without the variables, is pinned only in part:
  :func:`resolved` reads back what took effect, and that is what a record names.

``SOFTVT_NUMERICS`` chooses: ``x86-64-v3`` (the default), ``native`` (each library's own choice:
the numerics of every record made before the pins), or ``x86-64-v3:warp,aten`` (only the named
parts pinned; for measuring what moves what, ``scripts/numerics_matrix.py``). Why each part is
pinned and what it costs: docs/install.md and docs/benchmarks.md.
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass
from functools import lru_cache

NUMERICS_ENV = "SOFTVT_NUMERICS"
PINNED = "x86-64-v3"
NATIVE = "native"

# Warp 1.19's default flags with the target pinned. Warp's compiler treats "-march=native" itself (the
# host's CPU name and every feature it has, for the front end and the code generator) and hands any
# other flag to Clang's front end, where "-target-cpu" sets each function's target (the code
# generator is otherwise generic): so the object code depends on the source, the flags and Warp's
# LLVM, not on the host. Its inlining and SLP options only shape the code's speed.
WARP_PINNED_FLAGS = ("-target-cpu x86-64-v3 -mllvm=-inline-threshold=9000 -mllvm=-inline-cold-callsite-threshold=3000 "
                     "-mllvm=-slp-recursion-max-depth=4")
_AVX512_NUMPY = "AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR"

def cpu_flags() -> set[str]:
    """The CPU's feature flags as ``/proc/cpuinfo`` names them (x86 ``flags``, arm ``Features``)."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith(("flags", "Features")):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


# OpenCV warns on stderr, at every import, of each disabled feature the CPU lacks: name only those it
# has (AVX512-SKX is the only AVX-512 target its wheel dispatches to; F and COMMON come under it).
_AVX512_OPENCV = "AVX512F,AVX512-COMMON,AVX512-SKX" if {"avx512f", "avx512cd", "avx512bw", "avx512dq",
                                                        "avx512vl"} <= cpu_flags() else ""

# Each part: the variables that pin it (read by the library as it loads or first dispatches).
PARTS: dict[str, dict[str, str]] = {
    "warp": {},  # set on warp.config by physics/fem.py (warp_cpu_compiler_flags), not by a variable
    "aten": {"ATEN_CPU_CAPABILITY": "avx2"},  # torch's vectorised kernels (Sleef maths, reductions)
    "onednn": {"ONEDNN_MAX_CPU_ISA": "AVX2", "DNNL_MAX_CPU_ISA": "AVX2"},  # convolutions, bf16 products
    # torch's fp32 matrix products. MKL's AVX2 branch holds on Intel CPUs only: elsewhere MKL_CBWR=AVX2
    # falls back to MKL's AUTO branch (oneMKL Developer Guide, "Getting Started with Conditional
    # Numerical Reproducibility"), so goldens made on an AMD EPYC moved on an Intel Xeon (the VT-C
    # chunk by 1e-6). COMPATIBLE (SSE2 without rcpps/rsqrtps) is the branch MKL keeps the same on
    # Intel and compatible CPUs; a DP chunk measured no slower under it (0.40 s against 0.43 s).
    "mkl": {"MKL_CBWR": "COMPATIBLE", "MKL_ENABLE_INSTRUCTIONS": "AVX2"},
    # MKL's vector maths (VML: torch's float32 exp, sin, cos, square root; a policy's timestep embedding
    # and DDIM arithmetic) ignores MKL_CBWR's promise: under COMPATIBLE it runs its SSE4.2 kernels, whose
    # square root starts from rsqrtps, an approximation whose bits each CPU vendor defines (Intel's and
    # AMD's differ; the oneMKL reference, "Named Constants for CNR Control"): the likely cause of a
    # policy's Intel/AMD difference. Its CPU type 1 is the SSE2 kernels, which hold no rcpps/rsqrtps
    # (nor any other approximation instruction): measured on an Intel Xeon 2026-12-06, docs/install.md.
    # MKL_VML_DEBUG_CPU_TYPE is VML's own (undocumented) override, read at its first call; AMD CPUs honour
    # it too (an AMD EPYC, 2026-12-06: the policy goldens pass; resolved() reads back what VML runs).
    "vml": {"MKL_VML_DEBUG_CPU_TYPE": "1"},
    # The one float32 BLAS product of a policy's inference, the spatial softmax's expected keypoint
    # coordinates (softvt_campaign/baselines/networks.py), done as ATen's reduction, not MKL's GEMV:
    # MKL's GEMV path on AMD ignores MKL_CBWR (measured: AUTO, COMPATIBLE and AVX512 the same bits),
    # and an AMD EPYC's action chunk differed from an Intel Xeon's by 1e-6 under COMPATIBLE. Set in
    # code, not by a variable: the networks read the choice.
    "keypoints": {},
    "openblas": {"OPENBLAS_CORETYPE": "Haswell"},  # NumPy's linear algebra (the Kabsch SVD of D_t)
    "numpy": {"NPY_DISABLE_CPU_FEATURES": _AVX512_NUMPY},  # NumPy's own SIMD loops (exp, sin, sort...)
    "opencv": {"OPENCV_CPU_DISABLE": _AVX512_OPENCV} if _AVX512_OPENCV else {},  # the tactile optics' resizes
    "llvmpipe": {"LP_NATIVE_VECTOR_WIDTH": "256"},  # Mesa's software rasteriser (the cameras)
}

# Parts as earlier pins had them, named so that a record made under them is replayed under them
# (never chosen by default). "mkl-avx2": the pins until 2026-12-03 (package 0.1.0's records named
# them "x86-64-v3"), whose MKL branch depends on the CPU's vendor: such a record's policy products
# replay bit for bit only on CPUs of the vendor that made it (numerics_of names them so).
LEGACY_PARTS: dict[str, dict[str, str]] = {
    "mkl-avx2": {"MKL_CBWR": "AVX2", "MKL_ENABLE_INSTRUCTIONS": "AVX2"},
    # VML's own CPU detection, as every pin before 2026-12-06 left it: MKL reads a value that is not a
    # digit as no override (measured), and a Ray worker's runtime_env can set a variable, not unset it.
    "vml-detect": {"MKL_VML_DEBUG_CPU_TYPE": ""},
}
_ALL_PARTS = {**PARTS, **LEGACY_PARTS}
# The pinned choices of the earlier pins, as numerics_of spells them for their records: until
# 2026-12-03 (MKL's Intel-only branch), until 2026-12-05 (the keypoints through MKL's GEMV) and until
# 2026-12-06 (VML's per-vendor square root). All hold policy products bit for bit only on CPUs of the
# vendor that made them.
PINNED_MKL_AVX2 = f"{PINNED}:{','.join([*(p for p in PARTS if p not in ('mkl', 'keypoints', 'vml')), *LEGACY_PARTS])}"
PINNED_GEMV_KEYPOINTS = f"{PINNED}:{','.join([*(p for p in PARTS if p not in ('keypoints', 'vml')), 'vml-detect'])}"
PINNED_VENDOR_VML = f"{PINNED}:{','.join([*(p for p in PARTS if p != 'vml'), 'vml-detect'])}"
EARLIER_PINS = (PINNED_MKL_AVX2, PINNED_GEMV_KEYPOINTS, PINNED_VENDOR_VML)


@dataclass(frozen=True)
class Numerics:
    """A choice of numerics: its name as ``SOFTVT_NUMERICS`` spells it, and the parts it pins."""

    name: str
    parts: tuple[str, ...]

    @property
    def warp_cpu_compiler_flags(self) -> str | None:
        """The flags Warp compiles CPU kernels with (None: Warp's own default, ``-march=native``)."""
        return WARP_PINNED_FLAGS if "warp" in self.parts else None

    def environment(self) -> dict[str, str]:
        """The variables that pin this choice, ``SOFTVT_NUMERICS`` among them (for a spawned process)."""
        out = {NUMERICS_ENV: self.name}
        for part in self.parts:
            out.update(_ALL_PARTS[part])
        return out


def parse(name: str) -> Numerics:
    """``"x86-64-v3"``, ``"native"`` or ``"x86-64-v3:aten,warp"`` (a subset of :data:`PARTS`)."""
    name = (name or PINNED).strip()
    if name == NATIVE:
        return Numerics(NATIVE, ())
    base, _, subset = name.partition(":")
    if base != PINNED:
        raise ValueError(f"{NUMERICS_ENV}={name!r}: use {PINNED!r} (the default), {NATIVE!r}, or "
                         f"'{PINNED}:part,part' with parts from {', '.join(PARTS)}")
    parts = tuple(p.strip() for p in subset.split(",") if p.strip()) if subset else tuple(PARTS)
    unknown = [p for p in parts if p not in _ALL_PARTS]
    if unknown:
        raise ValueError(f"{NUMERICS_ENV}={name!r}: unknown part(s) {', '.join(unknown)}; parts are {', '.join(PARTS)}"
                         f" (and, to replay records of earlier pins, {', '.join(LEGACY_PARTS)})")
    for today, earlier in (("mkl", "mkl-avx2"), ("vml", "vml-detect")):
        if today in parts and earlier in parts:
            raise ValueError(f"{NUMERICS_ENV}={name!r}: {today} and {earlier} pin one library two ways; name one")
    ordered = tuple(p for p in _ALL_PARTS if p in parts)
    # One spelling per choice (records and demo sets compare names): the parts in PARTS' order.
    return Numerics(PINNED if ordered == tuple(PARTS) else f"{PINNED}:{','.join(ordered)}", ordered)


def chosen(environ=None) -> Numerics:
    """The numerics ``SOFTVT_NUMERICS`` chooses in ``environ`` (default: this process's)."""
    return parse((os.environ if environ is None else environ).get(NUMERICS_ENV, PINNED))


# The variables as the user's shell set them, before any pin: a process spawned for other numerics
# (``evaluate --reproduce`` of a record made before the pins) starts from these. Kept in the
# environment itself, so that a process spawned by a pinned one (a worker, an xdist worker) knows
# them too, and not the pins it inherited.
ORIGINAL_ENV = "SOFTVT_NUMERICS_ORIGINAL"
_ORIGINAL: dict[str, str | None] = {}
# The libraries that read their dispatch variables as they load, and the parts whose variables they read.
_READ_AT_LOAD = {"numpy": ("numpy", "openblas"), "torch": ("aten", "onednn", "mkl", "vml"), "cv2": ("opencv",)}
_LOADED_BEFORE: list[str] = []  # libraries that read their dispatch as they load, loaded before pin()
_RELEASED: set[str] = set()  # parts this process gave back to the library's own dispatch (release)


def _pinning_variables() -> list[str]:
    return sorted({v for part in _ALL_PARTS.values() for v in part})


def loaded_unpinned(loaded: list[str], environ, numerics: Numerics) -> list[str]:
    """Of the libraries ``loaded`` before :func:`pin`, those that may have read their dispatch under other
    variables than ``numerics`` pins: a library loaded while ``environ`` already held its pins read them
    (a Ray worker gets them from its runtime_env, then Ray itself imports NumPy before this package)."""
    def held(part):
        return all(environ.get(var) == value for var, value in _ALL_PARTS[part].items())
    return [m for m in loaded if not all(held(p) for p in _READ_AT_LOAD[m] if p in numerics.parts)]


def pin(environ=None) -> Numerics:
    """Set the variables of the chosen numerics in ``environ`` (default: this process's), overriding
    what was there (a record names its numerics, not the shell's), and return the choice."""
    environ = os.environ if environ is None else environ
    numerics = chosen(environ)
    if environ is os.environ and not _ORIGINAL:
        _LOADED_BEFORE.extend(loaded_unpinned([m for m in _READ_AT_LOAD if m in sys.modules], environ, numerics))
    if ORIGINAL_ENV in environ:
        # A variable an older version's parent did not know was unset as far as can be told (its
        # value here may be that parent's pin).
        original = {var: json.loads(environ[ORIGINAL_ENV]).get(var) for var in _pinning_variables()}
    else:
        original = {var: environ.get(var) for var in _pinning_variables()}
    environ[ORIGINAL_ENV] = json.dumps(original)
    if environ is os.environ:
        _ORIGINAL.update(original)
    # Every pinning variable as the choice has it: pinned, or as the shell had it (a process started by a
    # pinned one, for native numerics, must not keep the pins it inherited).
    for var in _pinning_variables():
        if original.get(var) is None:
            environ.pop(var, None)
        else:
            environ[var] = original[var]
    for var, value in numerics.environment().items():
        environ[var] = value
    return numerics


def release(part: str) -> None:
    """Give ``part`` back to its library's own dispatch in this process (the variables as the shell
    had them), where the library has not chosen yet: oneDNN chooses at its first primitive, so a
    bfloat16 training releases ``onednn`` before its first step (pinned to AVX2, oneDNN emulates
    bfloat16 and a training step costs 23x; docs/benchmarks.md). What the process then computes holds
    on machines of its kind only, and :func:`resolved` says so (``released``, ``pinned`` false)."""
    if part not in PARTS:
        raise ValueError(f"unknown part {part!r}; parts are {', '.join(PARTS)}")
    for var in PARTS[part]:
        original = _ORIGINAL.get(var)
        if original is None:
            os.environ.pop(var, None)
        else:
            os.environ[var] = original
    _RELEASED.add(part)
    resolved.cache_clear()


def environment(numerics: Numerics | str) -> dict[str, str | None]:
    """What a process spawned for ``numerics`` must start with: every variable of :data:`PARTS`,
    its pinned value or (for a part not pinned) the value this process had before :func:`pin`
    (None: unset)."""
    numerics = parse(numerics) if isinstance(numerics, str) else numerics
    out: dict[str, str | None] = {var: _ORIGINAL.get(var) if _ORIGINAL else os.environ.get(var)
                                  for var in _pinning_variables()}
    out.update(numerics.environment())
    return out


def _numpy_avx512() -> bool:
    try:  # NumPy 2 (the LeRobot stack); numpy.core is its deprecated alias
        from numpy._core._multiarray_umath import __cpu_features__
    except ImportError:  # NumPy 1
        from numpy.core._multiarray_umath import __cpu_features__
    return bool(__cpu_features__.get("AVX512_SKX") or __cpu_features__.get("AVX512F"))


def _openblas_core() -> str | None:
    """OpenBLAS's kernel family as NumPy's copy of it reports it (``Haswell``, ``SkylakeX``, ``Cooperlake``);
    None where it cannot be read (another BLAS)."""
    import ctypes
    import glob

    import numpy
    for lib in sorted(glob.glob(os.path.join(os.path.dirname(numpy.__file__), os.pardir, "numpy.libs", "*openblas*"))):
        for symbol in ("openblas_get_corename64_", "scipy_openblas_get_corename64_", "openblas_get_corename"):
            try:
                fn = getattr(ctypes.CDLL(lib), symbol)
            except (OSError, AttributeError):
                continue
            fn.restype = ctypes.c_char_p
            return fn().decode()
    return None


def vml_cpu_type() -> int | None:
    """The kernel family MKL's vector maths runs in this process (1: SSE2, the ``vml`` pin), read from
    the MKL that torch links (None: a torch without MKL). Asking fixes it, as VML's first call would:
    from MKL_VML_DEBUG_CPU_TYPE where set, else from the CPU."""
    import ctypes

    import torch
    try:
        lib = ctypes.CDLL(os.path.join(os.path.dirname(torch.__file__), "lib", "libtorch_cpu.so"))
        detect = lib.mkl_vml_serv_cpu_detect
    except (OSError, AttributeError):
        return None
    detect.restype = ctypes.c_int
    return detect()


@lru_cache(maxsize=1)
def resolved() -> dict:
    """What is in effect in this process, read back from the libraries where they tell (a record's
    ``numerics``): the chosen name, Warp's flags, torch's vector capability, MKL's vector-maths kernels,
    whether NumPy and OpenCV dispatch to AVX-512, OpenBLAS's kernel family, and the pinning variables as set. ``pinned`` is
    true when every part of the choice took effect (false, for example, when NumPy was imported
    before this package)."""
    import cv2
    import torch

    wp = configure_warp()
    numerics = chosen()
    env = {var: os.environ.get(var) for part in PARTS.values() for var in part}
    # "parts" tells a record of today's full pin from one of the earlier pins, which had the same name.
    out = {"name": numerics.name, "parts": list(numerics.parts), "warp_cpu_compiler_flags": wp.config.cpu_compiler_flags,
           "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
           "mkl_vml_cpu_type": vml_cpu_type(), "numpy_avx512": _numpy_avx512(), "opencv_avx512": "AVX512-SKX?" not in cv2.getCPUFeaturesLine()
           and "AVX512" in cv2.getCPUFeaturesLine(), "openblas_core": _openblas_core(),
           "environment": {k: v for k, v in sorted(env.items()) if v is not None},
           "loaded_before_pin": loaded_before_pin()}
    took = {"warp": out["warp_cpu_compiler_flags"] == WARP_PINNED_FLAGS,
            "aten": out["torch_cpu_capability"] in ("AVX2", "DEFAULT"),
            "numpy": not out["numpy_avx512"], "opencv": not out["opencv_avx512"],
            "openblas": out["openblas_core"] in (None, "Haswell"), "vml": out["mkl_vml_cpu_type"] in (None, 1)}
    out["released"] = sorted(_RELEASED)
    # Pinned: every part chosen, and each took effect (a subset of the parts holds on one machine kind only).
    out["pinned"] = numerics.parts == tuple(PARTS) and all(took.values()) and not _RELEASED
    return out


def loaded_before_pin() -> list[str]:
    """The libraries that read their dispatch as they load and were loaded before :func:`pin` ran
    (their pins may not have taken effect: :func:`resolved` tells)."""
    return list(_LOADED_BEFORE)


# Records made before the pins ran on each library's own dispatch, with whatever the machine's shell
# set: this workplace's AMD EPYC machines then set OPENBLAS_CORETYPE=Haswell (measured: VO-B's and the
# rigid VT-C's first ID episodes replay bit for bit with it on an AMD EPYC with AVX-512, and differ
# in the deformation trace's last bits without it). By the CPU model a pre-pin record names.
LEGACY_NUMERICS = {"AMD EPYC": f"{PINNED}:openblas"}


def numerics_of(record: dict, known: dict | None = None) -> str:
    """The numerics a record was made under: the name its receipt gives; for a record from before the
    numerics were pinned, what ``known`` (its file's provenance sidecar entry) says, else the machine's
    native dispatch as that kind of machine had it (:data:`LEGACY_NUMERICS`), ``native`` where unknown."""
    receipt = record.get("receipt") or {}
    if receipt.get("numerics"):
        numerics = receipt["numerics"]
        # The earlier pins were named as today's are; their MKL variables and their lack of "parts" tell them apart.
        if numerics["name"] == PINNED and (numerics.get("environment") or {}).get("MKL_CBWR") == "AVX2":
            return PINNED_MKL_AVX2
        if numerics["name"] == PINNED and "parts" not in numerics:
            return PINNED_GEMV_KEYPOINTS
        if numerics["name"] == PINNED and "vml" not in numerics["parts"]:  # the full pins before 2026-12-06
            return parse(f"{PINNED}:{','.join([*numerics['parts'], 'vml-detect'])}").name
        return numerics["name"]
    if known and known.get("numerics"):
        return known["numerics"]
    cpu = (receipt.get("stack") or {}).get("cpu") or ""
    return next((n for model, n in LEGACY_NUMERICS.items() if cpu.startswith(model)), NATIVE)


def vendor(cpu: str) -> str | None:
    """The CPU's vendor as its model name says it (``Intel(R) Xeon(R) ...``, ``AMD EPYC ...``)."""
    text = cpu.lower()
    return "intel" if "intel" in text else "amd" if "amd" in text else None


def machine_kind(stack: dict) -> tuple[str | None, tuple[str, ...]]:
    """(CPU model, its instruction-set features) of a stack as a record names it: what chooses the
    native numerics. The features are ``cpu-isa``'s CPU flags, without torch's capability and
    oneDNN's cap, which the numerics set, not the machine."""
    isa = (stack.get("cpu-isa") or "").split()
    return stack.get("cpu"), tuple(w for w in isa[1:] if not w.startswith("onednn_max="))


def pinned_in_full(record: dict) -> bool:
    """Whether ``record`` was made under today's pins with every part in effect (none released, nothing
    loaded before them): its bits hold on any x86-64 machine."""
    numerics = (record.get("receipt") or {}).get("numerics")
    return bool(numerics and numerics.get("pinned") and numerics_of(record) == PINNED)


def reproduction_note(record: dict, stack: dict, known: dict | None = None) -> str | None:
    """What a reproduction of ``record`` on a machine of ``stack`` (:func:`mani_skill_softvt.provenance.stack.software_stack`)
    should be told about its numerics: None when its numerics are pinned in full (they hold on any
    x86-64 machine); else whether this machine is of the kind (or, for the earlier pins, of the CPU
    vendor) that made it (``known``: its file's provenance sidecar entry, for a record that does not
    name its machine)."""
    numerics = (record.get("receipt") or {}).get("numerics")
    if pinned_in_full(record):
        return None
    earlier = numerics_of(record) if numerics else None
    # The earlier pins, all but a vendor-dependent MKL path, where every part took effect (a record that
    # completed an older file under them names them and is not "pinned", but released nothing).
    if earlier in EARLIER_PINS and not numerics.get("released") and not numerics.get("loaded_before_pin"):
        if not record.get("policy_sha256"):
            return None  # the expert runs no MKL: its records hold across vendors (measured, docs/install.md)
        made = ((record.get("receipt") or {}).get("stack") or {}).get("cpu") or "a CPU it does not name"
        here = stack.get("cpu") or "unknown"
        same = vendor(made) is not None and vendor(made) == vendor(here)
        what = {PINNED_MKL_AVX2: "whose MKL branch depends on the CPU's vendor",
                PINNED_GEMV_KEYPOINTS: "whose policy keypoints went through MKL's GEMV, which rounds otherwise on "
                                       "Intel and AMD CPUs",
                PINNED_VENDOR_VML: "whose policy square roots came from MKL's vector maths through rsqrtps, an "
                                   "approximation each CPU vendor rounds its own way"}[earlier]
        return (f"the records were made under the earlier pins ({earlier}), {what}, on {made}; this machine is {here}: "
                + ("of the same vendor, where they are expected to replay bit for bit" if same else
                   "the policy's products may round otherwise here, and their outcomes may differ"))
    made = (record.get("receipt") or {}).get("stack") or {}
    if not made.get("cpu") and known and known.get("cpu"):
        made = {"cpu": known["cpu"], "cpu-isa": known.get("cpu-isa")}
    how = ("made before the numerics were pinned" if not numerics else
           f"made with numerics {numerics.get('name')!r}, not pinned in full")
    if not made.get("cpu"):
        return (f"the records were {how} and do not name their machine: they replay bit for bit only on a machine "
                "of the kind that made them (docs/evaluation.md says which)")
    (cpu, flags), (here_cpu, here_flags) = machine_kind(made), machine_kind(stack)
    if not made.get("cpu-isa"):
        return (f"the records were {how} on {cpu} (its instruction set unrecorded): their bits hold only on a machine "
                f"of that kind; this one is {here_cpu} ({' '.join(here_flags)})")
    if (cpu, flags) == (here_cpu, here_flags):
        return f"the records were {how}; this machine is of the kind that made them ({cpu}, {' '.join(flags)})"
    return (f"the records were {how} on {cpu} ({' '.join(flags)}); this machine is {here_cpu} "
            f"({' '.join(here_flags)}): their bits hold only on a machine of that kind, their outcomes may differ here")


def configure_warp():
    """Import Warp with the chosen numerics' CPU compiler flags set (before any kernel compiles; the
    flags are part of Warp's kernel cache key, so kernels of other numerics are compiled apart)."""
    import warp as wp

    flags = chosen().warp_cpu_compiler_flags
    if flags is not None:
        wp.config.cpu_compiler_flags = flags
    return wp

