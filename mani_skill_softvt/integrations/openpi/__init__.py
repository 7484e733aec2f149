"""openpi's websocket protocol: a policy served elsewhere as a SoftVT policy (``remote``; specs
``ws://HOST:PORT``, registered as the policy kind ``remote``) and a server for an observation-only
SoftVT policy (``serve``). openpi's client is the optional ``remote`` extra (it needs NumPy < 2),
imported only when a server is used."""

from __future__ import annotations

from ...evaluation.policies import PolicyKind, PolicySource

REMOTE_PREFIXES = ("ws://", "wss://")
IMAGE_OBS_MODES = ("rgb", "rgb+tactile", "rgbd", "rgbd+tactile")  # what a policy server is sent (remote.py)


class RemoteKind(PolicyKind):
    """``ws://HOST:PORT`` (or ``wss://``): a policy server speaking openpi's protocol."""

    name = "remote"

    def matches(self, spec):
        return spec.startswith(REMOTE_PREFIXES)

    def resolve(self, spec):
        return PolicySource(spec, self.name, obs_modes=IMAGE_OBS_MODES)  # a server is sent camera images

    def load(self, source):
        try:
            from .remote import remote_policy_from_spec  # the optional extra, only when a server is used
        except ModuleNotFoundError as e:
            if e.name != "openpi_client":
                raise
            raise ValueError(f"--policy {source.spec} needs openpi's websocket client: pip install "
                             "'mani-skill-softvt[remote]' (openpi-client 0.1.2 needs NumPy < 2, so it is on the default "
                             "stack, scripts/setup.sh, not the LeRobot one)") from None
        return remote_policy_from_spec(source.spec)


REMOTE = RemoteKind()  # the entry point (pyproject.toml: mani_skill_softvt.policy_kinds)
