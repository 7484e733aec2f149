"""The GelSight model's settings as one frozen config: the gel, its grid, the markers' drawing and flow.

A sensor is built with one (``TactileSensor("left", config=TactileConfig(gel_modulus=1e6))``,
``GelSightConfig(..., tactile=...)`` as a camera config carries its intrinsics), and an env takes
plain overrides, ``gym.make(..., tactile={"gel_thickness": 1e-3})``, which ManiSkill records with
the env's kwargs. Each default is the constant beside its reasoning in :mod:`.constants`.

Not settings: the optics (taxim's photometric calibration of one GelSight Mini, its image size and
pixel pitch) and the 11 x 9 marker grid, which is part of the observation's shape. The package's
own commands (demos, evaluation, calibration) build their envs without overrides, so every frame
they render, and every policy trained on those frames, is of the defaults; the tactile model
version (:mod:`mani_skill_softvt.provenance`) names them.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from ..settings import with_overrides
from . import constants as C


@dataclass(frozen=True)
class TactileConfig:
    gel_modulus: float = C.GEL_MODULUS  # Pa, the elastomer's Young's modulus
    gel_poisson: float = C.GEL_POISSON  # its Poisson ratio, in [0, 0.5)
    gel_thickness: float = C.GEL_THICKNESS  # m: the gel's travel, its foundation depth and its flow layer
    grid_downsample: int = C.GEL_GRID_DOWNSAMPLE  # output pixels per gel-grid cell (divides 320 and 240)
    marker_radius: float = C.MARKER_RADIUS  # px of the drawn dots
    shear_decay: float = C.SHEAR_DECAY  # px: how far outside the contact the gel is dragged
    flow_pool: int = C.FLOW_POOL  # gel-grid px per side of the cells the flow sums over
    flow_surface_factor: float = C.FLOW_SURFACE_FACTOR  # surface motion over the layer's mean

    def __post_init__(self):
        positive = {"gel_modulus": self.gel_modulus, "gel_thickness": self.gel_thickness,
                    "marker_radius": self.marker_radius, "shear_decay": self.shear_decay,
                    "flow_surface_factor": self.flow_surface_factor}
        for name, value in positive.items():
            if not (isinstance(value, (int, float)) and value > 0 and value < float("inf")):
                raise ValueError(f"tactile setting {name}={value!r} must be a positive finite number")
        if not (isinstance(self.gel_poisson, (int, float)) and 0.0 <= self.gel_poisson < 0.5):
            raise ValueError(f"tactile setting gel_poisson={self.gel_poisson!r} must be in [0, 0.5) "
                             "(a thin bonded layer's confined modulus diverges at 0.5)")
        for name in ("grid_downsample", "flow_pool"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"tactile setting {name}={value!r} must be a whole number >= 1")
        k = self.grid_downsample
        if C.IMAGE_WIDTH % k or C.IMAGE_HEIGHT % k:
            raise ValueError(f"tactile setting grid_downsample={k} must divide the image's "
                             f"{C.IMAGE_WIDTH} x {C.IMAGE_HEIGHT} pixels")

    def with_overrides(self, overrides: dict | None = None, **more) -> "TactileConfig":
        """This config with some settings replaced; ValueError naming a setting that is not one."""
        return with_overrides(self, "tactile", overrides, **more)

    def signature(self) -> dict:
        """Every setting by name (plain numbers): what a user's record of an overridden sensor keeps."""
        return asdict(self)


DEFAULT_TACTILE = TactileConfig()
