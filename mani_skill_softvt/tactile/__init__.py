"""GelSight Mini tactile sensing: Taxim-style optics, FOTS-style markers (pure NumPy/OpenCV).

``TactileSensor(side).render(vertices_world, faces, pad_pose_world) -> TactileFrame``; the pad
frame and mirroring conventions are in :mod:`.sensor` and :mod:`.geometry`, the sensor
constants in :mod:`.constants`, the settings a user may change (the gel, its grid, the markers) in
one frozen :class:`TactileConfig` (:mod:`.config`). :class:`GelSight` wraps it as a ManiSkill sensor (:mod:`.gelsight`).
"""

from . import constants  # noqa: F401
from .constants import (  # noqa: F401
    FOV_HEIGHT,
    FOV_WIDTH,
    GEL_THICKNESS,
    IMAGE_HEIGHT,
    IMAGE_WIDTH,
    MARKER_COLS,
    MARKER_ROWS,
    PIXEL_SIZE,
)
from .config import DEFAULT_TACTILE, TactileConfig  # noqa: F401
from .gelsight import GelSight, GelSightConfig  # noqa: F401
from .sensor import TactileFrame, TactileSensor, finger_pad_frame, pad_frame  # noqa: F401

__all__ = [
    "GelSight", "GelSightConfig", "TactileConfig", "DEFAULT_TACTILE", "TactileSensor", "TactileFrame", "pad_frame", "finger_pad_frame", "constants",
    "IMAGE_WIDTH", "IMAGE_HEIGHT", "PIXEL_SIZE", "FOV_WIDTH", "FOV_HEIGHT", "GEL_THICKNESS",
    "MARKER_COLS", "MARKER_ROWS",
]
