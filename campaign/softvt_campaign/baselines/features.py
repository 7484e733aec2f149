"""What a Diffusion Policy baseline sees of one control step, as pure functions.

The same functions turn a rendered demonstration frame (training) and a live env observation
(evaluation) into the policy's inputs, so the two cannot drift apart:

- ``state``: the 7-D robot state of the paper, base-frame TCP position, TCP axis-angle and the
  gripper width. The axis-angle is taken on the branch nearest the top-down hand, (pi, 0, 0):
  the two representations of a near-half-turn differ by 2 pi in length, and a policy regressing
  across that jump would learn nonsense.
- ``base`` / ``hand``: the third-person and wrist RGB images, resized (area averaging).
- ``tactile_<side>``: the finger's GelSight image, with its depth map as a fourth channel when the
  config asks for it (``tactile_inputs``), resized.
- ``markers``: each finger's marker displacement from rest, (2, 99, 2) px; two frames of it are the
  paper's 792-D marker motion.
"""

from __future__ import annotations

import numpy as np

from mani_skill_softvt.data.images import resize_image
from mani_skill_softvt.contracts.observations import CAMERAS as ENV_CAMERAS, MARKER_FIELDS, QPOS, SIDES, TCP_POSE, camera_key, tactile_key
from mani_skill_softvt.physics.transforms import down_rotvec
from mani_skill_softvt.contracts.actions import base_frame_pose
from .config import DPConfig

# Bumped whenever frame_features computes anything differently: prepared training data is keyed by it.
FEATURES_VERSION = 1
CAMERAS = dict(zip(("base", "hand"), ENV_CAMERAS))  # input name -> the env's camera
DOWN_ROTVEC = down_rotvec(0.0)


def robot_state(tcp_pose_world: np.ndarray, gripper_width: float) -> np.ndarray:
    """The paper's 7-D robot state: base-frame TCP xyz, axis-angle (top-down branch), gripper width (m)."""
    return np.concatenate([base_frame_pose(tcp_pose_world, rotvec_reference=DOWN_ROTVEC),
                           [float(gripper_width)]]).astype(np.float32)


def tactile_image(rgb: np.ndarray, depth_um: np.ndarray | None, cfg: DPConfig) -> np.ndarray:
    """One finger's tactile stream, (h, w, 3 or 4) uint8: the image, and the depth map scaled so
    that ``cfg.depth_scale_um`` is 255 (clipped) when ``cfg.tactile_inputs`` is "rgb+depth"."""
    small = resize_image(rgb, cfg.tactile_size)
    if cfg.tactile_inputs == "rgb":
        return small
    if depth_um is None:
        raise ValueError("tactile_inputs 'rgb+depth' needs the tactile depth map; render observations "
                         "with obs_mode rgb+tactile from this version of the package")
    d = resize_image(np.asarray(depth_um, np.float32), cfg.tactile_size)
    d8 = np.clip(np.rint(d * (255.0 / cfg.depth_scale_um)), 0, 255).astype(np.uint8)
    return np.concatenate([small, d8[..., None]], axis=-1)


def marker_displacement(marker_initial: np.ndarray, marker_current: np.ndarray) -> np.ndarray:
    """Marker motion of one finger and frame: current minus rest position, (99, 2) px float32."""
    return (np.asarray(marker_current, np.float32) - np.asarray(marker_initial, np.float32)).reshape(-1, 2)


def frame_features(flat: dict, cfg: DPConfig) -> dict[str, np.ndarray]:
    """The policy inputs of one step from a flat observation (the flat keys of
    :mod:`mani_skill_softvt.contracts.observations`, one frame each: a rendered file's frame, or
    :func:`~mani_skill_softvt.contracts.observations.flatten_batch` of a live observation)."""
    # The jaw gap from the finger joints, as the env computes it: every observation path (env,
    # rendered file, policy server) carries qpos.
    width = float(np.asarray(flat[QPOS], np.float64).reshape(-1)[-2:].sum())
    out = {"state": robot_state(flat[TCP_POSE], width)}
    for name, cam in CAMERAS.items():
        out[name] = resize_image(np.asarray(flat[camera_key(cam)]), cfg.camera_size)
    if cfg.tactile:
        for side in SIDES:
            if tactile_key(side, "rgb") not in flat:
                raise ValueError(f"variant {cfg.variant} needs tactile observations: use obs_mode rgb+tactile")
            depth = flat.get(tactile_key(side, "depth"))
            out[f"tactile_{side}"] = tactile_image(np.asarray(flat[tactile_key(side, "rgb")]), depth, cfg)
        out["markers"] = np.stack([marker_displacement(*(flat[tactile_key(side, f)] for f in MARKER_FIELDS))
                                   for side in SIDES])
    return out


def image_keys(cfg: DPConfig) -> list[str]:
    """The image streams of the variant, each with its own encoder."""
    return list(CAMERAS) + ([f"tactile_{s}" for s in SIDES] if cfg.tactile else [])
