"""Out-of-process policies over openpi's websocket protocol (``ws://HOST:PORT``).

A policy server (an openpi ``serve_policy.py``, or :mod:`mani_skill_softvt.integrations.openpi.serve` for a project
policy) runs in its own process, possibly on another machine with a GPU; the evaluator talks to
it with :class:`WebsocketPolicy`, a :class:`~mani_skill_softvt.contracts.policy.Policy` like
any other. The wire format is openpi's: msgpack with numpy arrays (``openpi_client.msgpack_numpy``),
the server sends a metadata dict on connect, each request is one observation dict and each reply
is ``{"actions": (k, 7)}`` in the env's action space (``pd_ee_pose``: TCP position in the robot
base frame, axis-angle, gripper closure), or a string holding the server's traceback.

Observation schema (LIBERO-style keys, so an openpi LIBERO policy reads it unchanged):

- ``observation/image``: (H, W, 3) uint8, the third-person ``base_camera``;
- ``observation/wrist_image``: (H, W, 3) uint8, the wrist ``hand_camera``;
- ``rgbd`` and ``rgbd+tactile`` only: ``observation/image_depth`` and ``observation/wrist_image_depth``,
  (H, W, 1) int16, each camera's depth in millimetres along its optical axis (ManiSkill's depth;
  0 where nothing was hit), the pixels of the image beside it;
- ``observation/state``: (8,) float32, TCP xyz in the robot base frame, TCP axis-angle, the two
  finger joint positions;
- ``prompt``: str, the instruction;
- ``observation/qpos``: (9,) float32, all joint positions (the env's ``agent/qpos``);
- ``observation/tcp_pose_world``: (7,) float32, the env's ``extra/tcp_pose`` (world xyz + wxyz);
- ``rgb+tactile`` only, for SIDE in left, right: ``observation/tactile_SIDE`` (240, 320, 3) uint8
  GelSight image, ``observation/tactile_SIDE_markers_initial`` and ``..._markers_current``
  (99, 2) float32 marker pixel positions at rest and now;
- ``episode/reset``: bool, True in the first request of an episode; ``episode/seed``: int.

``state[:6]`` plus a gripper value is an action that holds the arm still. ``observation/qpos``
and ``observation/tcp_pose_world`` are lossless copies of what the env gives, so a project policy served by
:mod:`mani_skill_softvt.integrations.openpi.serve` computes bit for bit the actions it computes in process (the
base-frame position in ``state`` is rounded to float32 after the shift and cannot be shifted
back exactly). Nothing evaluator-only (FEM nodes, object poses, deformation, materials) is sent.

Episode start: openpi has no reset message, so the first request after
:meth:`WebsocketPolicy.reset` carries ``episode/reset: True`` (later ones ``False``) and every
request carries ``episode/seed``. Servers that do not know these keys ignore them (openpi's
input transforms pick the keys they need).
"""

from __future__ import annotations

import math
import urllib.parse

import numpy as np
import websockets.sync.client
from openpi_client import msgpack_numpy
from openpi_client.websocket_client_policy import WebsocketClientPolicy
from websockets.exceptions import ConnectionClosed

from ...contracts.observations import CAMERAS as ENV_CAMERAS, MARKER_FIELDS, QPOS, SIDES, TCP_POSE, camera_key, lookup, tactile_key
from ...contracts.policy import Policy
from ...contracts.actions import base_frame_pose

ACTION_DIM = 7
DEFAULT_CONNECT_TIMEOUT = 10.0  # s: TCP + websocket handshake + the server's metadata message
# s: one inference. Generous: a VLA server's first call may compile its model (minutes is rare, a
# minute is not); a server that stays silent longer is treated as hung.
DEFAULT_REPLY_TIMEOUT = 120.0
# Wire key -> the env's camera (LIBERO's names: third-person image, wrist image).
CAMERAS = dict(zip(("observation/image", "observation/wrist_image"), ENV_CAMERAS))
TACTILE_MARKERS = dict(zip(("markers_initial", "markers_current"), MARKER_FIELDS))  # wire suffix -> env field
QPOS_KEY, TCP_POSE_KEY, PROMPT_KEY = "observation/qpos", "observation/tcp_pose_world", "prompt"


def tactile_wire_key(side: str, suffix: str = "") -> str:
    """Wire key of one finger's tactile image (``suffix`` "") or of its ``depth`` / marker field."""
    return f"observation/tactile_{side}" + (f"_{suffix}" if suffix else "")


def depth_wire_key(image_key: str) -> str:
    """Wire key of a camera's depth image: its colour image's key with ``_depth``."""
    return f"{image_key}_depth"


EPISODE_RESET, EPISODE_SEED = "episode/reset", "episode/seed"


class RemotePolicyError(RuntimeError):
    """The policy server is unreachable, went away, timed out, failed, or replied nonsense."""


def base_frame_state(tcp_pose_world: np.ndarray, finger_qpos: np.ndarray) -> np.ndarray:
    """The 8-D LIBERO-style state: base-frame TCP xyz, TCP axis-angle, the two finger joints."""
    return np.concatenate([base_frame_pose(tcp_pose_world), np.asarray(finger_qpos).reshape(2)]).astype(np.float32)


def to_openpi_observation(obs: dict, instruction: str) -> dict:
    """An env observation (obs mode ``rgb`` or ``rgb+tactile``) as an openpi request (see module doc)."""
    if not isinstance(obs, dict) or "sensor_data" not in obs:
        raise ValueError("a remote policy needs camera images: evaluate with obs_mode rgb, rgbd, or either +tactile "
                         f"(got an observation with keys {sorted(obs) if isinstance(obs, dict) else type(obs)})")
    qpos = lookup(obs, QPOS).astype(np.float32)
    tcp_pose = lookup(obs, TCP_POSE).astype(np.float32)
    out = {key: np.ascontiguousarray(lookup(obs, camera_key(cam))) for key, cam in CAMERAS.items()}
    for key, cam in CAMERAS.items():
        try:  # rgbd modes
            out[depth_wire_key(key)] = np.ascontiguousarray(lookup(obs, camera_key(cam, "depth")))
        except KeyError:
            pass
    out.update({"observation/state": base_frame_state(tcp_pose, qpos[-2:]), QPOS_KEY: qpos,
                TCP_POSE_KEY: tcp_pose, PROMPT_KEY: str(instruction)})
    for side in SIDES if "tactile" in obs else ():
        out[tactile_wire_key(side)] = np.ascontiguousarray(lookup(obs, tactile_key(side, "rgb")))
        out[tactile_wire_key(side, "depth")] = np.ascontiguousarray(lookup(obs, tactile_key(side, "depth")))
        for name, field in TACTILE_MARKERS.items():
            out[tactile_wire_key(side, name)] = lookup(obs, tactile_key(side, field)).astype(np.float32)
    return out


def validate_actions(reply, url: str) -> np.ndarray:
    """The (k, 7) float action chunk of a server reply; RemotePolicyError naming ``url`` otherwise."""
    if isinstance(reply, str):  # openpi convention: a string reply is the server's traceback
        raise RemotePolicyError(f"the policy server at {url} failed:\n{reply}")
    if not isinstance(reply, dict) or "actions" not in reply:
        raise RemotePolicyError(f"the policy server at {url} replied without 'actions' "
                                f"({type(reply).__name__} with keys {sorted(reply) if isinstance(reply, dict) else '-'})")
    actions = reply["actions"]
    if not isinstance(actions, np.ndarray) or actions.dtype.kind != "f":
        raise RemotePolicyError(f"the policy server at {url} sent actions of type {type(actions).__name__} "
                                f"{getattr(actions, 'dtype', '')}: expected a float array of shape (k, {ACTION_DIM})")
    if actions.ndim != 2 or actions.shape[0] < 1 or actions.shape[1] != ACTION_DIM:
        raise RemotePolicyError(f"the policy server at {url} sent actions of shape {actions.shape}: expected "
                                f"(k, {ACTION_DIM}) with k >= 1 (pd_ee_pose: base-frame xyz, axis-angle, gripper)")
    if not np.isfinite(actions).all():
        raise RemotePolicyError(f"the policy server at {url} sent non-finite actions: {actions.tolist()}")
    return actions.copy()  # unpacked arrays are read-only views of the message


class _BoundedClient(WebsocketClientPolicy):
    """openpi's websocket client (URI handling, msgpack-numpy packer, metadata) with bounded
    connect and receive times: openpi's blocks without limit on both."""

    def __init__(self, url: str, connect_timeout: float, reply_timeout: float):
        self._connect_timeout, self._reply_timeout = connect_timeout, reply_timeout
        super().__init__(url)  # connects: calls _wait_for_server

    def _wait_for_server(self):
        conn = websockets.sync.client.connect(self._uri, compression=None, max_size=None,
                                              open_timeout=self._connect_timeout, close_timeout=1.0)
        try:
            return conn, msgpack_numpy.unpackb(conn.recv(timeout=self._connect_timeout))
        except BaseException:
            conn.close()
            raise

    def infer(self, obs: dict):
        """The unpacked reply, or the server's traceback string as is (validate_actions reads it)."""
        self._ws.send(self._packer.pack(obs))
        reply = self._ws.recv(timeout=self._reply_timeout)
        return reply if isinstance(reply, str) else msgpack_numpy.unpackb(reply)

    def close(self) -> None:
        self._ws.close()


class WebsocketPolicy(Policy):
    """A policy served over openpi's websocket protocol at ``url`` (``ws://HOST:PORT``).

    Connects in :meth:`reset` (the server's metadata is then in :attr:`metadata`), not on
    construction, so that an unreachable server fails each episode as a ``policy_error`` record
    instead of the whole evaluation, and a server that comes back is used again. Every failure (refused
    connection, handshake or metadata slower than ``connect_timeout``, no reply within
    ``reply_timeout``, a dropped connection, a traceback or a malformed reply) raises
    :class:`RemotePolicyError` naming the URL. After a transport failure the connection is closed
    (a late reply would otherwise answer the next request); the next :meth:`reset` reconnects.
    """

    def __init__(self, url: str, connect_timeout: float = DEFAULT_CONNECT_TIMEOUT,
                 reply_timeout: float = DEFAULT_REPLY_TIMEOUT):
        if not url.startswith(("ws://", "wss://")):
            raise ValueError(f"remote policy URL '{url}' must start with ws:// or wss://")
        for name, value in (("connect_timeout", connect_timeout), ("reply_timeout", reply_timeout)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {value!r}")
        self.url, self.connect_timeout, self.reply_timeout = url, float(connect_timeout), float(reply_timeout)
        self._client, self.metadata = None, None
        self.name = f"remote[?]@{url}"  # the served policy's name once connected
        self._instruction, self._seed, self._new_episode = "", 0, True

    def _connect(self) -> None:
        try:
            self._client = _BoundedClient(self.url, self.connect_timeout, self.reply_timeout)
        except TimeoutError as e:
            raise RemotePolicyError(f"the policy server at {self.url} did not complete the handshake and send its "
                                    f"metadata within {self.connect_timeout} s") from e
        except Exception as e:  # refused, unknown host, bad handshake: all "not there"
            raise RemotePolicyError(f"cannot connect to the policy server at {self.url}: {type(e).__name__}: {e}. "
                                    "Is it running (python -m mani_skill_softvt.integrations.openpi.serve POLICY --port PORT)?") from e
        self.metadata = self._client.get_server_metadata()
        served = self.metadata.get("policy") if isinstance(self.metadata, dict) else None
        self.name = f"remote[{served or '?'}]@{self.url}"

    def _check_camera_size(self, request: dict) -> None:
        """A server that says its policy takes another camera size than the evaluator renders is an
        error naming the flag, not a policy silently fed resized images."""
        wanted = self.metadata.get("camera_size") if isinstance(self.metadata, dict) else None
        got = [list(request[key].shape[:2]) for key in CAMERAS]
        if wanted is not None and any(g != list(wanted) for g in got):
            raise RemotePolicyError(f"the policy served at {self.url} takes {wanted[0]}x{wanted[1]} cameras and this "
                                    f"evaluation renders {got[0][0]}x{got[0][1]}: evaluate with --camera-size "
                                    f"{wanted[0]}x{wanted[1]}")

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def reset(self, instruction: str, seed: int) -> None:
        if self._client is None:  # first episode, or the last one lost the connection
            self._connect()
        self._instruction, self._seed, self._new_episode = instruction, int(seed), True

    def act(self, obs) -> np.ndarray:
        if self._client is None:
            raise RemotePolicyError(f"not connected to the policy server at {self.url}: the connection was lost "
                                    "earlier in this episode, or reset() was not called; reset() connects")
        request = to_openpi_observation(obs, self._instruction)
        self._check_camera_size(request)
        request.update({EPISODE_RESET: self._new_episode, EPISODE_SEED: self._seed})
        try:
            reply = self._client.infer(request)
        except TimeoutError as e:
            self.close()
            raise RemotePolicyError(f"the policy server at {self.url} sent no reply within {self.reply_timeout} s "
                                    "(raise reply_timeout: ws://HOST:PORT?reply_timeout=SECONDS)") from e
        except (ConnectionClosed, OSError) as e:  # the server went away (or the network did)
            self.close()
            raise RemotePolicyError(f"the connection to the policy server at {self.url} was lost: "
                                    f"{type(e).__name__}: {e}") from e
        self._new_episode = False
        return validate_actions(reply, self.url)


def remote_policy_from_spec(spec: str) -> WebsocketPolicy:
    """``ws://HOST:PORT[?connect_timeout=S&reply_timeout=S]`` as a :class:`WebsocketPolicy`.

    The query is read here and not sent to the server. ``policies.load_policy`` hands every
    ``ws://`` / ``wss://`` spec to this function.
    """
    parts = urllib.parse.urlsplit(spec)
    if parts.scheme not in ("ws", "wss") or not parts.hostname:
        raise ValueError(f"remote policy '{spec}' must look like ws://HOST:PORT")
    options = {}
    for key, values in urllib.parse.parse_qs(parts.query, keep_blank_values=True).items():
        if key not in ("connect_timeout", "reply_timeout"):
            raise ValueError(f"remote policy '{spec}': unknown option '{key}' (known: connect_timeout, reply_timeout)")
        try:
            options[key] = float(values[-1])
        except ValueError:
            raise ValueError(f"remote policy '{spec}': {key} must be a number of seconds, got '{values[-1]}'") from None
    return WebsocketPolicy(urllib.parse.urlunsplit(parts._replace(query="", fragment="")), **options)
