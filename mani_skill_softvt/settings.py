"""What the package's frozen settings objects share (physics/config.py, tactile/config.py).

MuJoCo Playground's pattern: one frozen config with defaults, overridden by plain values (which
ManiSkill records with an env's kwargs), never by patching module constants.
"""

from __future__ import annotations

from dataclasses import fields, replace


def with_overrides(config, kind: str, overrides: dict | None = None, **more):
    """``config`` (a frozen dataclass) with some fields replaced; ValueError naming any key that is
    not one of its fields (``kind`` names the settings in the message: "physics", "tactile")."""
    if overrides is not None and not isinstance(overrides, dict):
        raise TypeError(f"{kind}={overrides!r}: give a dict of overrides (dataclasses.asdict(config) for a "
                        f"{type(config).__name__}), which ManiSkill can record")
    given = {**(overrides or {}), **more}
    known = {f.name for f in fields(config)}
    unknown = sorted(set(given) - known)
    if unknown:
        raise ValueError(f"{kind} settings {unknown} are not settings; give some of {sorted(known)}")
    return replace(config, **given)
