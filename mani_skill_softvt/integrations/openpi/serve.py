"""Serve a project policy over openpi's websocket protocol, for ``--policy ws://HOST:PORT``.

    python -m mani_skill_softvt.integrations.openpi.serve random --port 8000                  # a built-in policy
    python -m mani_skill_softvt.integrations.openpi.serve mypkg.policies:MyPolicy --port 8000 --host 0.0.0.0

The counterpart of :class:`mani_skill_softvt.integrations.openpi.remote.WebsocketPolicy` (the protocol
and the observation schema are documented there): the policy runs in this process, e.g. on a GPU
machine, while the evaluator steps the env elsewhere. On connect the server sends its metadata;
each request is turned back into the observation dict the env produces (``agent/qpos``,
``extra/tcp_pose``, both cameras, tactile when sent; as batched torch tensors; the instruction goes to ``reset``),
so the policy computes bit for bit the actions it computes in process. ``episode/reset`` (and the
first request of a connection) calls ``reset(prompt, episode/seed)``. A policy exception is
answered with its traceback (a string, openpi's convention) and the server keeps serving.

Each connection gets its own policy instance, so parallel evaluation workers do not share
episode state. Privileged policies (the scripted expert) need the env and cannot be served.
Binds to 127.0.0.1 unless ``--host`` says otherwise: the protocol has no authentication.
"""

from __future__ import annotations

import argparse
import traceback

import numpy as np
import torch

from ...version import __version__
from ...evaluation.policies import BUILTIN, resolve_policy
from .remote import (
    ACTION_DIM,
    CAMERAS,
    EPISODE_RESET,
    EPISODE_SEED,
    PROMPT_KEY,
    QPOS_KEY,
    TACTILE_MARKERS,
    TCP_POSE_KEY,
    depth_wire_key,
    tactile_wire_key,
)
from ...contracts.observations import QPOS, SIDES, TCP_POSE, camera_key, nest, tactile_key
from ...contracts.policy import is_privileged

DEFAULT_PORT = 8000  # openpi's default


def _batched(x, dtype=None):
    """A numpy array from the wire as the env's batched (1, ...) torch tensor (a writable copy)."""
    return torch.from_numpy(np.array(x, dtype=dtype)[None])


def from_openpi_observation(request: dict) -> tuple[dict, str]:
    """The env-style observation dict and the instruction of an openpi request (inverse of
    :func:`~mani_skill_softvt.integrations.openpi.remote.to_openpi_observation` on the keys it sends)."""
    needed = [*CAMERAS, QPOS_KEY, TCP_POSE_KEY, PROMPT_KEY]
    missing = [k for k in needed if k not in request]
    if missing:
        raise KeyError(f"request lacks {missing}: a project policy needs the lossless keys that "
                       "mani_skill_softvt.integrations.openpi.remote.WebsocketPolicy sends")
    instruction = str(request[PROMPT_KEY])
    flat = {QPOS: _batched(request[QPOS_KEY], np.float32), TCP_POSE: _batched(request[TCP_POSE_KEY], np.float32),
            **{camera_key(cam): _batched(request[key], np.uint8) for key, cam in CAMERAS.items()}}
    for key, cam in CAMERAS.items():
        if depth_wire_key(key) in request:  # rgbd modes
            flat[camera_key(cam, "depth")] = _batched(request[depth_wire_key(key)], np.int16)
    if tactile_wire_key(SIDES[0]) in request:
        for side in SIDES:
            flat[tactile_key(side, "rgb")] = _batched(request[tactile_wire_key(side)], np.uint8)
            for name, field in TACTILE_MARKERS.items():
                flat[tactile_key(side, field)] = _batched(request[tactile_wire_key(side, name)], np.float32)
            if tactile_wire_key(side, "depth") in request:  # a client of an older package sends no depth map
                flat[tactile_key(side, "depth")] = _batched(request[tactile_wire_key(side, "depth")], np.int16)
    return nest(flat), instruction


def _servable() -> list[str]:
    """Built-in policies that read observations only (the scripted experts need the env)."""
    return [k for k, c in BUILTIN.items() if not is_privileged(c)]


def make_policy_factory(spec: str):
    """A zero-argument constructor of the policy ``spec``, its name and the camera size it asks
    for; ValueError for privileged policies."""
    if spec in BUILTIN and is_privileged(BUILTIN[spec]):
        raise ValueError(f"policy '{spec}' is privileged (it plans on the env's simulator state) and cannot be "
                         f"served; serve an observation-only policy: {', '.join(_servable())} or module:Class")
    source = resolve_policy(spec)  # resolved once; each connection builds its policy from it
    probe = source.load()  # fails now, not on the first connection
    if is_privileged(probe):
        raise ValueError(f"policy '{spec}' is privileged (it needs the env) and cannot be served")
    return source.load, getattr(probe, "name", type(probe).__name__), source.camera_size



def _chunk(policy, obs: dict) -> np.ndarray:
    """The policy's action chunk as the (k, 7) float32 array sent back; ValueError for another shape."""
    actions = np.asarray(policy.act(obs), dtype=np.float32)
    if actions.ndim != 2 or actions.shape[1] != ACTION_DIM or actions.shape[0] < 1:
        raise ValueError(f"policy {getattr(policy, 'name', policy)} returned actions of shape {actions.shape}, "
                         f"expected (k, {ACTION_DIM})")
    return actions


def build_server(policy_factory, name: str, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 camera_size: list[int] | None = None):
    """A websockets sync server (not yet serving: call ``serve_forever``; ``shutdown`` stops it)."""
    # openpi-client and websockets are the optional ``remote`` extra (NumPy < 2): imported only to serve.
    import websockets.sync.server
    from openpi_client import msgpack_numpy
    from websockets.exceptions import ConnectionClosed

    # "server" keeps the name clients have seen (the module moved to integrations/openpi/ in session 30)
    metadata = {"policy": name, "server": "mani_skill_softvt.serve", "package_version": __version__,
                "action_space": "pd_ee_pose: (k, 7) TCP xyz in the robot base frame, axis-angle, gripper closure",
                "episode_keys": [EPISODE_RESET, EPISODE_SEED]}
    if camera_size is not None:  # the evaluator must render its cameras at this size (evaluate --camera-size)
        metadata["camera_size"] = list(camera_size)

    def handler(conn) -> None:
        policy = policy_factory()
        started = False
        try:
            conn.send(msgpack_numpy.packb(metadata))
            for message in conn:
                try:
                    request = msgpack_numpy.unpackb(message)
                    obs, instruction = from_openpi_observation(request)
                    if request.get(EPISODE_RESET) or not started:  # a client that never says so gets one reset
                        policy.reset(instruction, int(request.get(EPISODE_SEED, 0)))
                        started = True
                    actions = _chunk(policy, obs)
                except Exception:  # the client gets the traceback; the next request is served
                    conn.send(traceback.format_exc())
                    continue
                conn.send(msgpack_numpy.packb({"actions": actions}))
        except ConnectionClosed:  # the client went away: nothing to answer
            pass

    return websockets.sync.server.serve(handler, host, port, compression=None, max_size=None)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.integrations.openpi.serve", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("policy", help=f"a built-in policy ({', '.join(_servable())}) "
                                   "or module:Class (constructed without arguments)")
    ap.add_argument("--port", type=int, default=DEFAULT_PORT, help="TCP port (0: any free port, printed)")
    ap.add_argument("--host", default="127.0.0.1", help="address to bind (0.0.0.0 for every interface)")
    args = ap.parse_args(argv)
    if not 0 <= args.port <= 65535:
        ap.error(f"--port must be in [0, 65535], got {args.port}")
    try:
        factory, name, size = make_policy_factory(args.policy)  # size: what the evaluator would render in process
    except (ValueError, FileNotFoundError) as e:
        ap.error(str(e))
    try:
        server = build_server(factory, name, args.host, args.port, None if size is None else list(size))
    except OSError as e:  # port taken, address not local
        ap.error(f"cannot listen on {args.host}:{args.port}: {e}; choose another --port (0: any free one)")
    with server:
        host, port = server.socket.getsockname()[:2]
        print(f"serving policy {name} on ws://{host}:{port}", flush=True)
        try:
            server.serve_forever()
        except KeyboardInterrupt:
            pass


if __name__ == "__main__":
    main()
