"""The policy contract: what the evaluator, the policy server and every policy agree on.

A policy sees observations only: ``reset(instruction, seed)`` at each episode start, then
``act(obs) -> (k, d)`` action chunks in the env's control mode, each executed for up to the
runner's ``replan_steps`` before the next call. ``name`` labels its records.

A policy that was trained on camera images of another size than the env's 224x224 says so in
``camera_size`` = (height, width): the evaluator renders its cameras at that size (ManiSkill's
``sensor_configs``), so it sees what it was trained on rather than a shrunken 224x224 image.

A policy that plans from a window of recent frames need not see every step's camera images: it
says so through ``needs_next_images()``, which the evaluator asks after each ``act``. When it
returns False, the evaluator does not render the cameras of the step that follows, and that
step's observation carries no camera images (``obs["sensor_data"]`` is empty; state, extra and
tactile entries are as always). In evaluation the observations of the steps inside a chunk of
k > 1 actions reach no policy, so their cameras are not rendered either. Rendering reads the
scene and never changes it: the episode is the same bit for bit either way, minus the cameras'
cost (a fifth of an evaluation step at 84 px, docs/benchmarks.md). Episode videos render every
step and do not ask. A policy served over ``ws://`` is always sent images.

A *privileged* policy (``privileged = True``: the scripted experts) plans on the simulator: the
runner hands it the env through ``bind(env)`` before ``reset`` and labels its records so; it
cannot be served over the network. Every other policy, in process or behind ``ws://``, never
holds the env.

This module imports nothing of the package, so policies, the evaluator and the server all build
on it without import cycles.
"""

from __future__ import annotations

import numpy as np


class Policy:
    """What the evaluator calls: ``reset`` at each episode start, ``act`` for each action chunk."""

    name = "policy"
    privileged = False
    camera_size: tuple[int, int] | None = None  # None: the env's native 224x224

    def bind(self, env) -> None:
        """The env a privileged policy plans on (called by the runner before ``reset``)."""
        raise TypeError(f"{type(self).__name__} is not privileged: it sees observations only")

    def reset(self, instruction: str, seed: int) -> None:
        raise NotImplementedError

    def act(self, obs) -> np.ndarray:
        raise NotImplementedError

    def needs_next_images(self) -> bool:
        """Whether the observation passed to the next ``act`` must carry camera images (asked
        after each ``act``; by default always)."""
        return True


def is_privileged(policy) -> bool:
    """Whether ``policy`` (an instance or a class; any object with the contract's methods) reads the simulator."""
    return bool(getattr(policy, "privileged", False))
