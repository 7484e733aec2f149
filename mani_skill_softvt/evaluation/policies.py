"""The policy interface of the evaluation and the built-in policies.

The contract (``reset``, ``act``, ``name``, ``privileged``) is :mod:`mani_skill_softvt.policy`.
Only the built-in scripted experts are privileged: the runner binds them to the env they plan on
and labels their records so; every other policy (in process, or served over ``ws://``) never
holds the env.
"""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np

from ..expert.policy import CartesianExpertPolicy, ScriptedExpertPolicy  # noqa: F401  (built in; re-exported)
from ..policy import Policy  # noqa: F401  (the contract; re-exported for user code that imported it here)


def _tcp_action(obs, closure: float) -> np.ndarray:
    """An action holding the TCP pose read from the observation (state_dict / rgb modes)."""
    from ..observations import TCP_POSE, lookup
    from ..tasks.robot import base_frame_pose

    try:
        pose = lookup(obs, TCP_POSE).reshape(-1)[:7]
    except (KeyError, TypeError):
        raise ValueError(f"this policy reads the observation's {TCP_POSE}: use obs_mode state_dict, rgb or "
                         "rgb+tactile") from None
    return np.concatenate([base_frame_pose(pose), [closure]]).astype(np.float32)


class HoldPolicy(Policy):
    """Baseline: keep the initial TCP pose, gripper open (never succeeds, never squeezes)."""

    name = "hold"

    def reset(self, instruction: str, seed: int) -> None:
        self._action = None

    def act(self, obs) -> np.ndarray:
        if self._action is None:
            self._action = _tcp_action(obs, 0.0)
        return self._action[None]


class RandomPolicy(Policy):
    """Baseline: random TCP targets within 5 cm of the start and random closures (seeded)."""

    name = "random"

    def reset(self, instruction: str, seed: int) -> None:
        self.rng = np.random.default_rng([seed, 11])
        self._home = None

    def act(self, obs) -> np.ndarray:
        if self._home is None:
            self._home = _tcp_action(obs, 0.0)
        a = self._home.copy()
        a[:3] += self.rng.uniform(-0.05, 0.05, 3)
        a[6] = self.rng.uniform(0.0, 1.0)
        return a[None]


BUILTIN = {"expert": ScriptedExpertPolicy, "expert_cartesian": CartesianExpertPolicy, "hold": HoldPolicy,
           "random": RandomPolicy}


def policy_camera_size(spec: str) -> tuple[int, int] | None:
    """The camera size (height, width) the policy ``spec`` asks for (:attr:`Policy.camera_size`),
    read without building it: a baseline's ``policy.pt`` says it, a ``module:Class`` as a class
    attribute; built-in policies and policy servers (whose size the evaluator is told,
    ``evaluate --camera-size``) take the env's."""
    if spec.endswith(".pt"):
        from ..baselines.agent import camera_render_size, read_policy_file

        return camera_render_size(read_policy_file(Path(spec))[1])
    if spec in BUILTIN or spec.startswith(("ws://", "wss://")) or ":" not in spec:
        return None
    module, cls = spec.split(":", 1)
    try:
        size = getattr(getattr(importlib.import_module(module), cls), "camera_size", None)
    except (ImportError, AttributeError) as e:
        raise ValueError(f"cannot load policy '{spec}': {e}") from e
    return None if size is None else tuple(int(v) for v in size)


def load_policy(spec: str) -> Policy:
    """A built-in policy name, ``module:Class`` of a user policy (constructed without arguments),
    ``ws://HOST:PORT`` of a policy server, or the ``policy.pt`` of a trained baseline."""
    if spec in BUILTIN:
        return BUILTIN[spec]()
    if spec.endswith(".pt"):  # a trained Diffusion Policy baseline (mani_skill_softvt.baselines)
        from ..baselines.agent import DiffusionPolicyAgent
        return DiffusionPolicyAgent(spec)
    if spec.startswith(("ws://", "wss://")):  # a policy server (openpi protocol), see evaluation/remote.py
        try:
            from .remote import remote_policy_from_spec
        except ModuleNotFoundError as e:
            if e.name != "openpi_client":
                raise
            raise ValueError(f"--policy {spec} needs openpi's websocket client: pip install 'mani-skill-softvt[remote]' "
                             "(openpi-client 0.1.2 needs NumPy < 2, so it is on the default stack, scripts/setup.sh, "
                             "not the LeRobot one)") from None
        return remote_policy_from_spec(spec)
    if ":" not in spec:
        raise ValueError(f"policy '{spec}' is neither built in ({sorted(BUILTIN)}) nor of the form module:Class")
    module, cls = spec.split(":", 1)
    try:
        obj = getattr(importlib.import_module(module), cls)
    except (ImportError, AttributeError) as e:
        raise ValueError(f"cannot load policy '{spec}': {e}") from e
    policy = obj()
    for method in ("reset", "act"):
        if not callable(getattr(policy, method, None)):
            raise ValueError(f"policy '{spec}' has no {method}() method")
    return policy
