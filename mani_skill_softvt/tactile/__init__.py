"""GelSight Mini tactile sensing: Taxim-style optics, FOTS-style markers (pure NumPy/OpenCV)."""

from .sensor import TactileFrame, TactileSensor, pad_frame  # noqa: F401
