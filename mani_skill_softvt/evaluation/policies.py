"""The policy door of the evaluation: every way a policy is named, resolved once, and the built-in policies.

The contract (``reset``, ``act``, ``name``, ``privileged``) is :mod:`mani_skill_softvt.contracts.policy`.
Only the built-in scripted experts are privileged: the runner binds them to the env they plan on
and labels their records so; every other policy (in process, or served over ``ws://``) never
holds the env.

A policy is named by a spec: a built-in name (``expert``, ``hold``, ...), ``module:Class``,
``ws://HOST:PORT`` of a policy server, or a file another package knows how to read (the trained
baselines' ``.pt``). :func:`resolve_policy` turns a spec into a :class:`PolicySource` once, in the
process that starts a run: its kind, the SHA-256 of its file, and what it needs of the env (the
obs and control modes it was trained for, its camera size), read from one read of the file. The
source is what workers get; :meth:`PolicySource.load` builds the policy from it.

Kinds other than the built-in names and ``module:Class`` register themselves as entry points of the
group ``mani_skill_softvt.policy_kinds`` (a :class:`PolicyKind`): the baselines register their policy
files there, openpi's integration its ``ws://`` servers (``pyproject.toml``), so the evaluation
imports neither, and any package can add its own kind the same way.
"""

from __future__ import annotations

import importlib
import sys
from dataclasses import dataclass
from functools import lru_cache
from importlib import metadata

import numpy as np
from tqdm import tqdm

from ..expert.policy import CartesianExpertPolicy, ScriptedExpertPolicy  # noqa: F401  (built in; re-exported)
from ..contracts.observations import TCP_POSE, lookup
from ..provenance import moved_data_path
from ..contracts.policy import Policy  # noqa: F401  (the contract; re-exported for user code that imported it here)
from ..contracts.actions import base_frame_pose

POLICY_KINDS_GROUP = "mani_skill_softvt.policy_kinds"


@dataclass(frozen=True)
class PolicySource:
    """A policy spec, resolved (module docstring). ``obs_modes`` / ``control_modes``: those it can
    run in (None: any; the first is its default), ``camera_size``: (height, width) it was trained
    on (None: the env's native size); ``sha256``: of its file, for a policy that is one;
    ``tactile_model``: the tactile model of the frames it learned from (None: it reads no touch,
    or nothing is known of its training)."""

    spec: str
    kind: str
    sha256: str | None = None
    obs_modes: tuple[str, ...] | None = None
    control_modes: tuple[str, ...] | None = None
    camera_size: tuple[int, int] | None = None
    tactile_model: int | None = None

    def load(self) -> Policy:
        return policy_kind(self.kind).load(self)


class PolicyKind:
    """One way of naming a policy: which specs are its, what a spec resolves to, how to build it."""

    name: str = ""

    def matches(self, spec: str) -> bool:
        raise NotImplementedError

    def resolve(self, spec: str) -> PolicySource:
        return PolicySource(spec, self.name)

    def load(self, source: PolicySource) -> Policy:
        raise NotImplementedError


class _BuiltinKind(PolicyKind):
    name = "builtin"

    def matches(self, spec):
        return spec in BUILTIN

    def load(self, source):
        return BUILTIN[source.spec]()


class _ClassKind(PolicyKind):
    """``module:Class``: user code, imported and constructed without arguments in each process. The
    class may say what it runs in: ``camera_size``, ``obs_modes`` and ``control_modes`` (the first of
    each its default), as a resolved source does."""

    name = "class"

    def matches(self, spec):
        return ":" in spec

    def _class(self, spec):
        module, cls = spec.split(":", 1)
        try:
            return getattr(importlib.import_module(module), cls)
        except (ImportError, AttributeError) as e:
            raise ValueError(f"cannot load policy '{spec}': {e}") from e

    def resolve(self, spec):
        cls = self._class(spec)
        size = getattr(cls, "camera_size", None)
        modes = {k: tuple(getattr(cls, k)) if getattr(cls, k, None) else None for k in ("obs_modes", "control_modes")}
        return PolicySource(spec, self.name, camera_size=None if size is None else tuple(int(v) for v in size), **modes)

    def load(self, source):
        policy = self._class(source.spec)()
        for method in ("reset", "act"):
            if not callable(getattr(policy, method, None)):
                raise ValueError(f"policy '{source.spec}' has no {method}() method")
        return policy


_OWN_KINDS = (_BuiltinKind(),)  # tried first: naming them loads no other package
_CLASS_KIND = _ClassKind()  # tried last: any "a:b" would match it


@lru_cache(maxsize=1)
def _registered_kinds() -> tuple[tuple[str, PolicyKind | Exception], ...]:
    """The kinds installed packages register, loaded once on first need (a kind that fails to
    load is kept as its error, so it spoils only the specs that would have been its own)."""
    out = []
    for ep in sorted(metadata.entry_points(group=POLICY_KINDS_GROUP), key=lambda e: e.name):
        try:
            out.append((ep.name, ep.load()))
        except Exception as e:  # noqa: BLE001 - another package's import error is reported, not raised here
            out.append((ep.name, e))
    return tuple(out)


def policy_kind(name: str) -> PolicyKind:
    """The kind called ``name`` (the package's own without loading any registered one)."""
    for kind in (*_OWN_KINDS, _CLASS_KIND):
        if kind.name == name:
            return kind
    for kind_name, kind in _registered_kinds():
        if kind_name == name or getattr(kind, "name", None) == name:
            if isinstance(kind, Exception):
                raise ValueError(f"the policy kind '{kind_name}' could not be loaded: {kind}")
            return kind
    raise ValueError(f"no policy kind '{name}' is installed "
                     f"(registered: {[n for n, _ in _registered_kinds()]})")


def resolve_policy(spec: str) -> PolicySource:
    """The :class:`PolicySource` of ``spec``: tried on the built-in names, then the registered kinds
    (``ws://`` servers, policy files), then ``module:Class``; ValueError naming the spec for one no kind takes.
    A policy file named in its folder's old spelling (``baselines/policies/...``) is read where it lies
    now, with a note on stderr."""
    spec = str(spec)
    moved = moved_data_path(spec)
    if moved is not None:
        _note_moved(spec, moved)
        spec = moved
    for kind in _OWN_KINDS:
        if kind.matches(spec):
            return kind.resolve(spec)
    broken = []
    for name, kind in _registered_kinds():
        if isinstance(kind, Exception):
            broken.append(f"{name} ({type(kind).__name__}: {kind})")
        elif kind.matches(spec):
            return kind.resolve(spec)
    if _CLASS_KIND.matches(spec):
        return _CLASS_KIND.resolve(spec)
    registered = [n for n, k in _registered_kinds() if not isinstance(k, Exception)]
    raise ValueError(f"policy '{spec}' is neither built in ({sorted(BUILTIN)}), module:Class, ws://HOST:PORT, nor a "
                     f"file an installed policy kind reads (registered: {registered or 'none'}; a trained baseline's .pt "
                     "is read once the campaign is installed: pip install -e campaign, as scripts/setup.sh does)"
                     + (f"; kinds that failed to load: {', '.join(broken)}" if broken else ""))


@lru_cache(maxsize=None)  # once a process and path: a run resolves its policy in every worker
def _note_moved(spec: str, moved: str) -> None:
    # tqdm.write: a run's progress bar may be on screen; the note goes above it, not onto its line
    tqdm.write(f"note: policy {spec}: that folder was renamed; reading {moved}", file=sys.stderr)


def load_policy(spec: str) -> Policy:
    """The policy ``spec`` names, built (:func:`resolve_policy`, then :meth:`PolicySource.load`)."""
    return resolve_policy(spec).load()


def _tcp_action(obs, closure: float) -> np.ndarray:
    """An action holding the TCP pose read from the observation (any obs mode but none)."""
    try:
        pose = lookup(obs, TCP_POSE).reshape(-1)[:7]
    except (KeyError, TypeError):
        raise ValueError(f"this policy reads the observation's {TCP_POSE}: use any obs mode but none") from None
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
