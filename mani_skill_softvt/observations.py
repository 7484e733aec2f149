"""The observation and info contract of every SoftVT env: the one place that names what an env
observes and reports, and how to read it.

Observations hold arrays only, nested as ManiSkill nests them, each with a batch axis of one
(``num_envs`` is 1). Flattened with ``/`` (:func:`flatten_batch`, as the rendered demo files,
the baselines and the LeRobot export store them), one frame is:

| key | shape | dtype | obs modes |
|---|---|---|---|
| ``agent/qpos``, ``agent/qvel`` | (9,) | float32 | all but ``none`` |
| ``extra/tcp_pose`` | (7,) world xyz + wxyz | float32 | all but ``none`` |
| ``extra/gripper_width`` | (1,) m | float32 | all but ``none`` |
| ``sensor_data/base_camera/rgb``, ``sensor_data/hand_camera/rgb`` | (224, 224, 3) | uint8 | ``rgb``, ``rgb+tactile`` |
| ``tactile/<side>/rgb`` (side ``left``, ``right``) | (240, 320, 3) GelSight image | uint8 | ``rgb+tactile`` |
| ``tactile/<side>/depth`` | (240, 320) gel indentation, micrometres | int16 | ``rgb+tactile`` |
| ``tactile/<side>/marker_initial``, ``.../marker_current`` | (99, 2) marker pixels at rest, now | float32 | ``rgb+tactile`` |

(``state`` is the same proprioception flattened into one vector; camera sizes follow the env's
``sensor_configs``: :func:`camera_sensor_configs` renders both cameras at another size, e.g. the
84x84 a CPU policy takes, instead of rendering 224x224 and shrinking.) The instruction is ``env.unwrapped.instruction``, never an observation.

``info`` from the env holds booleans as batch-of-one tensors (``success``, ``fail``,
``is_grasped``, ``dropped``, ``in_target``, ``other_in_target``);
:class:`~mani_skill_softvt.evaluation.wrapper.DSRWrapper` adds plain values
(``deformation_ratio``, ``r_max``, ``task_success``, ``collapsed_tets``, ``collapsed_steps``,
``dsr_success``). :func:`info_bool` reads
either form.
"""

from __future__ import annotations

import numpy as np

CAMERAS = ("base_camera", "hand_camera")  # third-person, wrist
SIDES = ("left", "right")  # the fingers, each with a GelSight
MARKER_FIELDS = ("marker_initial", "marker_current")
TACTILE_FIELDS = ("rgb", "depth", *MARKER_FIELDS)
QPOS, QVEL = "agent/qpos", "agent/qvel"
TCP_POSE, GRIPPER_WIDTH = "extra/tcp_pose", "extra/gripper_width"
NATIVE_CAMERA_SIZE = (224, 224)  # (height, width) of both cameras by default (the paper's views)


def camera_sensor_configs(camera_size: tuple[int, int] | None) -> dict:
    """ManiSkill ``sensor_configs`` that render both cameras at ``camera_size`` = (height, width);
    empty for None or the native size. (The GelSights are not cameras: their 240x320 image is
    the sensor's.)"""
    if camera_size is None or tuple(camera_size) == NATIVE_CAMERA_SIZE:
        return {}
    h, w = (int(v) for v in camera_size)
    if min(h, w) < 8:
        raise ValueError(f"camera_size {tuple(camera_size)}: give (height, width), each at least 8 pixels")
    return {"width": w, "height": h}


def parse_image_size(text: str, flag: str = "--image-size") -> tuple[int, int] | None:
    """``HxW`` on a command line -> (H, W); ``native`` -> None (each stream keeps its size)."""
    if text == "native":
        return None
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"{flag} {text!r}: give HxW (e.g. 84x84) or 'native'") from None
    return h, w


def camera_size_name(camera_size: tuple[int, int] | None) -> str:
    """``84x84``: how a camera size appears in file names and on the command line."""
    h, w = camera_size or NATIVE_CAMERA_SIZE
    return f"{h}x{w}"


def camera_key(camera: str) -> str:
    """Flat key of a camera's RGB image."""
    return f"sensor_data/{camera}/rgb"


def tactile_key(side: str, field: str) -> str:
    """Flat key of one finger's tactile field (``rgb``, ``depth``, ``marker_initial``, ``marker_current``)."""
    return f"tactile/{side}/{field}"


def tactile_keys(fields=TACTILE_FIELDS) -> list[str]:
    """Flat keys of ``fields`` of both fingers, side by side."""
    return [tactile_key(s, f) for s in SIDES for f in fields]


def unbatch(x) -> np.ndarray:
    """A batch-of-one array (torch or numpy, (1, ...)) as its single numpy element; unbatched
    arrays pass through."""
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    x = np.asarray(x)
    return x[0] if x.ndim and x.shape[0] == 1 else x


def flatten_batch(tree: dict, prefix: str = "") -> dict[str, np.ndarray]:
    """An observation or env state (nested dicts, batch of one) as ``{"a/b": array}`` without the
    batch axis: the rendered files' keys, and what a baseline policy reads live."""
    out = {}
    for k, v in tree.items():
        key = f"{prefix}/{k}" if prefix else k
        if isinstance(v, dict):
            out.update(flatten_batch(v, key))
        else:
            out[key] = np.asarray(v.cpu().numpy() if hasattr(v, "cpu") else v)[0]
    return out


def nest(flat: dict) -> dict:
    """``{"a/b": value}`` as nested dicts ``{"a": {"b": value}}`` (the inverse of flattening)."""
    out: dict = {}
    for key, value in flat.items():
        node = out
        *parents, leaf = key.split("/")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return out


def lookup(obs: dict, key: str) -> np.ndarray:
    """The value at flat ``key`` of a nested observation, unbatched; KeyError naming the key."""
    node = obs
    for part in key.split("/"):
        if not isinstance(node, dict) or part not in node:
            raise KeyError(key)
        node = node[part]
    return unbatch(node)


def as_bool(v) -> bool:
    """A batch-of-one boolean (tensor or array, as the env's ``terminated`` and ``info`` flags) or a plain one."""
    return bool(v.reshape(-1)[0]) if hasattr(v, "reshape") else bool(v)


def info_bool(info: dict, key: str, default: bool = False) -> bool:
    """A boolean of ``info``: a batch-of-one tensor from the env, or a plain value from a wrapper."""
    return as_bool(info.get(key, default))
