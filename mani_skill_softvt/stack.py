"""The software stack a result was made on, named in every evaluation record.

The same episode on another stack (another torch, NumPy, Warp, Newton or SAPIEN, another Python)
keeps its outcome but not its bits; a record that names its stack lets ``evaluate --reproduce``
say why a reproduction differs instead of leaving it unexplained.
"""

from __future__ import annotations

import platform
from functools import lru_cache
from importlib import metadata

import cv2
import torch

from .version import __version__

# The distributions whose arithmetic reaches a record: the physics (warp, newton, sapien), the
# policy's network and sampler (torch, diffusers), the array maths (numpy) and ManiSkill's env glue.
STACK_DISTRIBUTIONS = ("torch", "numpy", "warp-lang", "newton", "sapien", "mani-skill", "diffusers")


def cpu_model() -> str:
    """The processor's model name: machines of one kind can differ in it (an AMD EPYC and an Intel
    Xeon round the same episode differently, and a learned policy's closed loop amplifies that)."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


@lru_cache(maxsize=1)
def _stack() -> tuple[tuple[str, str | None], ...]:
    out = {"python": platform.python_version(), "mani-skill-softvt": __version__, "opencv": cv2.__version__,
           "cpu": cpu_model()}
    for dist in STACK_DISTRIBUTIONS:
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = None
    out["torch"] = torch.__version__
    return tuple(out.items())


def software_stack() -> dict[str, str | None]:
    """``{"python": ..., "mani-skill-softvt": ..., "torch": ..., "opencv": ..., ...}`` of this process
    (a new dict each call: records do not share one)."""
    return dict(_stack())


def stack_differences(recorded: dict | None, current: dict) -> list[str]:
    """``["torch 2.13.0 -> 2.11.0", ...]``: what differs between a recorded stack and this one
    (empty when they are the same or the record predates stacks being recorded)."""
    if not recorded:
        return []
    return [f"{k} {recorded.get(k)} -> {current.get(k)}" for k in sorted(set(recorded) | set(current))
            if recorded.get(k) != current.get(k)]
