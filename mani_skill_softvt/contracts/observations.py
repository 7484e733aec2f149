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

The camera modes beyond ``rgb`` (:class:`ObsMode`) add, per camera, ManiSkill's textures:
``sensor_data/<camera>/depth`` (H, W, 1) int16 mm, ``.../segmentation`` (H, W, 1) int16 ids of the
env's ``segmentation_id_map``, ``.../position`` (H, W, 3) int16 mm in the camera's frame,
``.../normal`` (H, W, 3) float32; ``pointcloud`` replaces the cameras' images by
``pointcloud/xyzw`` (N, 4) float32 world points (w 1 where a surface was hit), ``pointcloud/rgb``
(N, 3) uint8 and ``pointcloud/segmentation`` (N, 1) int16, N the cameras' pixels; ``sensor_data``
gives the renderer's raw ``Color`` and ``PositionSegmentation``; ``sensor_param/<camera>`` carries
each camera's ``intrinsic_cv``, ``extrinsic_cv`` and ``cam2world_gl``; a "+state" mode replaces
``agent`` and ``extra`` by the flat ``state``.

(``state`` is the same proprioception flattened into one vector, :data:`STATE_LAYOUT`; camera sizes follow the env's
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

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

CAMERAS = ("base_camera", "hand_camera")  # third-person, wrist
TACTILE_SUFFIX = "+tactile"  # "<camera mode>+tactile": the camera mode plus both fingers' GelSight
# ManiSkill's camera textures (mani_skill.envs.utils.observations.ALL_VISUAL_TEXTURES), and its named
# modes that stand for sets of them (parse_obs_mode_to_struct): one vocabulary with ManiSkill's.
TEXTURES = ("rgb", "depth", "segmentation", "position", "normal", "albedo")
NAMED_TEXTURE_MODES = {"rgbd": ("rgb", "depth"), "pointcloud": ("rgb", "position", "segmentation"),
                       "sensor_data": ("rgb", "depth", "segmentation", "position")}
STATE_PARTS = ("state", "state_dict")  # "+state": the proprioception flattened beside the images
# The modes named in help texts and docs; any "+" combination of TEXTURES (with "+state" or "+tactile")
# is accepted as well (ObsMode.parse).
OBS_MODES = ("state", "state_dict", "none", "rgb", "rgb+tactile", "depth", "depth+tactile", "rgbd", "rgbd+tactile",
             "rgb+depth+segmentation", "rgb+depth+segmentation+tactile", "pointcloud", "pointcloud+tactile",
             "sensor_data", "sensor_data+tactile")
DEFAULT_OBS_MODE = "state"  # ManiSkill's default: the first of an env's SUPPORTED_OBS_MODES
SIDES = ("left", "right")  # the fingers, each with a GelSight
MARKER_FIELDS = ("marker_initial", "marker_current")
TACTILE_FIELDS = ("rgb", "depth", *MARKER_FIELDS)
QPOS, QVEL = "agent/qpos", "agent/qvel"
TCP_POSE, GRIPPER_WIDTH = "extra/tcp_pose", "extra/gripper_width"
# The flat ``state`` vector (obs mode ``state``; ``state`` of a "+state" mode): ManiSkill flattens
# ``agent`` then ``extra`` in this order.
STATE_LAYOUT = ((QPOS, 9), (QVEL, 9), (TCP_POSE, 7), (GRIPPER_WIDTH, 1))


class CameraSize(NamedTuple):
    """(height, width) of both policy cameras: the one type a camera size has in this package.
    Every spelling one is given in becomes one through :meth:`of`: None and ``"native"`` (the
    cameras' own 224x224, the paper's views), ``"HxW"`` on a command line, a (height, width) pair
    from a record, a policy file or a config. A tuple itself, so it compares and serialises as one.
    (The GelSights are not cameras: their 240x320 image is the sensor's.)"""

    height: int
    width: int

    @classmethod
    def of(cls, value, what: str = "camera_size") -> "CameraSize":
        """``value`` as a camera size; ValueError naming ``what`` (a flag, a field) and what to give."""
        if value is None or value == "native":
            return NATIVE_CAMERA_SIZE
        try:
            h, w = (int(v) for v in (value.lower().split("x") if isinstance(value, str) else value))
        except (TypeError, ValueError):
            raise ValueError(f"{what} {value!r}: give HxW (e.g. 84x84), (height, width), or 'native'") from None
        if min(h, w) < 8:
            raise ValueError(f"{what} {h}x{w}: give (height, width), each at least 8 pixels")
        return cls(h, w)

    @property
    def native(self) -> bool:
        return self == NATIVE_CAMERA_SIZE

    @property
    def name(self) -> str:
        """``84x84``: how a camera size appears in file names and on the command line."""
        return f"{self.height}x{self.width}"

    def sensor_configs(self) -> dict:
        """ManiSkill ``sensor_configs`` that render both cameras at this size (empty when native)."""
        return {} if self.native else {"width": self.width, "height": self.height}


NATIVE_CAMERA_SIZE = CameraSize(224, 224)  # both cameras by default (the paper's views)


@dataclass(frozen=True)
class ObsMode:
    """An obs mode, parsed: ``camera`` is the part ManiSkill parses (``rgbd``, ``pointcloud``,
    ``rgb+depth+state``, ``state``...), ``tactile`` whether "+tactile" adds both GelSights, ``textures``
    the camera textures it renders. The one place that says what a mode name means here."""

    name: str
    camera: str
    tactile: bool
    textures: frozenset

    @classmethod
    def parse(cls, obs_mode: str | None) -> "ObsMode":
        """``obs_mode`` checked; ValueError naming it and what to give instead."""
        name = DEFAULT_OBS_MODE if obs_mode is None else obs_mode
        camera = name.removesuffix(TACTILE_SUFFIX)
        parts = camera.split("+")
        textures = set()
        for part in parts:
            if part in NAMED_TEXTURE_MODES and len(parts) == 1 or part == "pointcloud":
                textures.update(NAMED_TEXTURE_MODES[part])
            elif part in TEXTURES:
                textures.add(part)
            elif part not in STATE_PARTS and not (part == "none" and len(parts) == 1):
                raise ValueError(f"obs_mode '{name}': '{part}' is not an obs mode or camera texture; give one of "
                                 f"{', '.join(OBS_MODES)}, or a '+' combination of {', '.join(TEXTURES)} (with "
                                 "'+state', and '+tactile' last)")
        if name.endswith(TACTILE_SUFFIX) and not textures:
            raise ValueError(f"obs_mode '{name}': touch comes with camera images (e.g. 'rgb+tactile', "
                             f"'pointcloud+tactile'); the state modes are proprioception only")
        return cls(name, camera, name.endswith(TACTILE_SUFFIX), frozenset(textures))

    @property
    def images(self) -> bool:
        """Whether the cameras render (any texture)."""
        return bool(self.textures)

    @property
    def pointcloud(self) -> bool:
        """Whether the cameras' textures become one world-frame point cloud (ManiSkill's ``pointcloud``)."""
        return "pointcloud" in self.camera.split("+")

    @property
    def shader_pack(self) -> str:
        """The cameras' shader: ManiSkill's ``minimal`` (colour, position, segmentation, depth) unless the
        mode asks for ``normal`` or ``albedo``, which only its ``default`` pack renders (its colour is
        shaded differently: an ``rgb+normal`` image is not an ``rgb`` one)."""
        return "default" if self.textures & {"normal", "albedo"} else "minimal"

    @property
    def raw(self) -> bool:
        """``sensor_data``: the renderer's raw textures (ManiSkill applies no texture transforms)."""
        return self.camera == "sensor_data"


def is_native_camera_size(camera_size) -> bool:
    """Whether ``camera_size`` (any spelling :meth:`CameraSize.of` takes) is the cameras' own 224x224."""
    return CameraSize.of(camera_size).native


def camera_sensor_configs(camera_size) -> dict:
    """ManiSkill ``sensor_configs`` that render both cameras at ``camera_size`` (:meth:`CameraSize.of`);
    empty for None or the native size."""
    return CameraSize.of(camera_size).sensor_configs()


def parse_image_size(text: str, flag: str = "--image-size") -> tuple[int, int] | None:
    """``HxW`` on a command line -> (H, W); ``native`` -> None (each stream keeps its own size: an
    image size, for every stream; a camera size is :meth:`CameraSize.of`)."""
    return None if text == "native" else tuple(CameraSize.of(text, flag))


def camera_size_name(camera_size) -> str:
    """``84x84``: how a camera size appears in file names and on the command line."""
    return CameraSize.of(camera_size).name


def camera_key(camera: str, texture: str = "rgb") -> str:
    """Flat key of a camera's image (``texture``: rgb, depth, segmentation...)."""
    return f"sensor_data/{camera}/{texture}"


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


def state_slice(key: str) -> slice:
    """Where ``key`` (``agent/qpos`` ... ``extra/gripper_width``) lies in the flat ``state`` vector."""
    start = 0
    for name, size in STATE_LAYOUT:
        if name == key:
            return slice(start, start + size)
        start += size
    raise KeyError(key)


def lookup(obs, key: str) -> np.ndarray:
    """The value at flat ``key`` of an observation, unbatched; KeyError naming the key. A proprioceptive
    key is also read from the flat state (obs mode ``state``, or ``obs["state"]`` of a "+state" mode)."""
    node = obs
    for part in key.split("/"):
        if not isinstance(node, dict) or part not in node:
            flat = obs.get("state") if isinstance(obs, dict) else obs
            if flat is None or isinstance(flat, dict) or key not in dict(STATE_LAYOUT):
                raise KeyError(key)
            return unbatch(flat)[..., state_slice(key)]
        node = node[part]
    return unbatch(node)


def as_bool(v) -> bool:
    """A batch-of-one boolean (tensor or array, as the env's ``terminated`` and ``info`` flags) or a plain one."""
    return bool(v.reshape(-1)[0]) if hasattr(v, "reshape") else bool(v)


def info_bool(info: dict, key: str, default: bool = False) -> bool:
    """A boolean of ``info``: a batch-of-one tensor from the env, or a plain value from a wrapper."""
    return as_bool(info.get(key, default))
