"""The GelSight Mini as a ManiSkill sensor: configured like a camera, captured with the cameras.

``GelSightConfig("tactile_left", side="left")`` beside the ``CameraConfig`` entries of an env;
the env builds one :class:`GelSight` per config in its sensor setup. Each capture renders the
finger's frame from three callables the env hands over: the contact surface (the deformed
object meshes, world frame), the pad's 4x4 world pose and the simulated normal force on the pad
given that pose (it sets how deep the gel sinks, :mod:`.gel`), and whether the objects are FEM
bodies or rigid twins (which gel model applies). The sensor itself holds no simulator
handle, so the optics (:class:`~mani_skill_softvt.tactile.sensor.TactileSensor`) stay pure.

Observation of one finger: ``{"rgb": (1, 240, 320, 3) uint8, "depth": (1, 240, 320) int16 gel
indentation in micrometres (int16 like ManiSkill's camera depth), "marker_initial": (1, 99, 2) float32 px, "marker_current": (1, 99, 2)
float32 px}``. The depth map is what a GelSight's photometric-stereo reconstruction gives; it is
part of the observation because on objects softer than the gel (the foods and foams here) the
indentation is tens of micrometres and the RGB change is faint (docs/tactile.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from mani_skill.sensors.base_sensor import BaseSensor, BaseSensorConfig

from .config import DEFAULT_TACTILE, TactileConfig
from .sensor import SIDES, TactileFrame, TactileSensor

DEPTH_UNIT = 1e-6  # m per count of the int16 depth observation (the gel is 2 mm thick: <= 2000 counts)


def depth_counts(depth: np.ndarray) -> np.ndarray:
    """A gel indentation map (m) as the observation's int16 micrometres (rounded, clipped)."""
    return np.clip(np.rint(np.asarray(depth) / DEPTH_UNIT), 0, np.iinfo(np.int16).max).astype(np.int16)


@dataclass
class GelSightConfig(BaseSensorConfig):
    """A GelSight Mini on one Panda finger (``side`` "left" or "right")."""

    side: str = "left"
    # Half extents (x along image columns, y along rows; m) of the gel the finger carries: no
    # contact is shown outside it. None: the whole field of view.
    pad_half_extents: tuple[float, float] | None = None
    # The gel, its grid and the markers (tactile.config), as a camera config carries its intrinsics.
    tactile: TactileConfig = DEFAULT_TACTILE

    def __post_init__(self):
        if self.side not in SIDES:
            raise ValueError(f"GelSightConfig side must be one of {SIDES}, got {self.side!r}")
        if not isinstance(self.tactile, TactileConfig):
            raise TypeError(f"GelSightConfig tactile must be a TactileConfig, got {self.tactile!r}")


class GelSight(BaseSensor):
    """One finger's tactile sensor in a ManiSkill scene (see the module docstring)."""

    config: GelSightConfig

    def __init__(self, config: GelSightConfig, contact_surface: Callable[[], tuple[np.ndarray, np.ndarray]],
                 pad_pose: Callable[[], np.ndarray], normal_force: Callable[[np.ndarray], float] | None = None,
                 deformable: bool = True):
        super().__init__(config)
        self.deformable = deformable  # FEM surfaces (pressure indentation) or rigid twins (force balance)
        self.renderer = TactileSensor(config.side, pad_half_extents=config.pad_half_extents, config=config.tactile)
        self._contact_surface = contact_surface
        self._pad_pose = pad_pose
        self._normal_force = normal_force
        self.frame: TactileFrame | None = None

    @property
    def side(self) -> str:
        return self.config.side

    def reset(self) -> None:
        """Start of an episode: forget the contact onset (marker shear is measured from it)."""
        self.renderer.reset()
        self.frame = None

    def capture(self) -> None:
        vertices, faces = self._contact_surface()
        pose = self._pad_pose()
        force = None if self._normal_force is None else self._normal_force(pose)
        self.frame = self.renderer.render(vertices, faces, pose, force, self.deformable)

    def get_obs(self, **kwargs) -> dict[str, torch.Tensor]:
        if self.frame is None:
            self.capture()
        f = self.frame
        return {"rgb": torch.from_numpy(f.image[None].copy()),
                "depth": torch.from_numpy(depth_counts(f.depth)[None]),
                "marker_initial": torch.from_numpy(f.marker_initial[None].copy()),
                "marker_current": torch.from_numpy(f.marker_current[None].copy())}

    def get_images(self, obs: dict | None = None) -> dict[str, torch.Tensor]:
        """What ``render_mode="sensors"`` shows: the tactile RGB frame (as ManiSkill's cameras, a dict)."""
        return {"rgb": (obs or self.get_obs())["rgb"]}

    def get_params(self) -> dict:
        return {}  # no camera intrinsics: the frame's geometry is fixed (tactile.constants)
