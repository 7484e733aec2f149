"""The per-finger GelSight Mini sensor: contact mesh + gel pose in, tactile image + markers out.

Frames. The *pad frame* has its origin at the centre of the gel surface and +z along the gel's
outward normal (towards the grasped object); x runs along image columns, y along image rows.
Each finger's pad frame is right-handed, so with both x axes chosen along the hand's x the two
images are mirror images of each other, as the two cameras look at the object from opposite
sides (the right finger's x points along -x of the hand; see :func:`pad_frame`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import constants as C
from .geometry import contact_mask, penetration_map, rigid_fit_2d, to_pixels
from .markers import draw_markers, marker_displacements, marker_grid
from .optics import load_calibration, render_image


@dataclass
class TactileFrame:
    image: np.ndarray  # (240, 320, 3) uint8 RGB, markers drawn
    marker_initial: np.ndarray  # (99, 2) float32 (col, row) px
    marker_current: np.ndarray  # (99, 2) float32 (col, row) px
    depth: np.ndarray  # (240, 320) penetration (m): sensor-internal, for tests and figures


def pad_frame(origin: np.ndarray, normal: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """4x4 world pose of a pad frame: +z along ``normal``, +x along ``x_hint`` made orthogonal."""
    z = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    x = np.asarray(x_hint, np.float64) - np.dot(x_hint, z) * z
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, np.cross(z, x), z, origin
    return m


class TactileSensor:
    """One GelSight Mini on one finger. Call :meth:`reset` at episode start, :meth:`render` per frame."""

    def __init__(self, side: str = "left"):
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        self.side = side
        self.calib = load_calibration()
        self.marker_initial = marker_grid()
        self.background_frame = draw_markers(self.calib.background, self.marker_initial)
        self.reset()

    def reset(self) -> None:
        self._onset: tuple[np.ndarray, np.ndarray] | None = None  # (vertex ids, pad xy at onset)

    def render(self, vertices_world: np.ndarray, faces: np.ndarray, pad_pose_world: np.ndarray) -> TactileFrame:
        """Frame for the object surface (world vertices, triangles) touching this pad."""
        m = np.asarray(pad_pose_world, np.float64)
        if m.shape != (4, 4):
            raise ValueError(f"pad_pose_world must be a 4x4 matrix, got shape {m.shape}")
        v = np.asarray(vertices_world, np.float64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"vertices_world must have shape (N, 3), got {v.shape}")
        local = (v - m[:3, 3]) @ m[:3, :3]
        return self.render_local(local, faces)

    def render_local(self, vertices_pad: np.ndarray, faces: np.ndarray) -> TactileFrame:
        """Frame for a surface already expressed in the pad frame."""
        depth = penetration_map(vertices_pad, faces)
        mask = contact_mask(depth)
        if not mask.any():
            self._onset = None
            return TactileFrame(self.background_frame.copy(), self.marker_initial.astype(np.float32),
                                self.marker_initial.astype(np.float32), depth)
        shear_px, twist = self._patch_motion(vertices_pad)
        current = marker_displacements(self.marker_initial, depth / C.PIXEL_SIZE, mask, shear_px, twist)
        image = draw_markers(render_image(depth, self.calib), current)
        return TactileFrame(image, self.marker_initial.astype(np.float32), current.astype(np.float32), depth)

    def _patch_motion(self, vertices_pad: np.ndarray) -> tuple[np.ndarray, float]:
        """Shear (px) and twist (rad) of the contact patch since onset, from the vertices that
        were in contact at onset (2-D rigid fit of their in-plane motion)."""
        in_contact = np.nonzero(vertices_pad[:, 2] < 0.0)[0]
        if self._onset is None or len(in_contact) == 0:
            ids = in_contact if len(in_contact) else np.argsort(vertices_pad[:, 2])[:3]
            self._onset = (ids, vertices_pad[ids, :2].copy())
            return np.zeros(2), 0.0
        ids, xy0 = self._onset
        if len(ids) < 2:
            shift = vertices_pad[ids, :2].mean(axis=0) - xy0.mean(axis=0)
            return shift / C.PIXEL_SIZE, 0.0
        angle, shift = rigid_fit_2d(xy0, vertices_pad[ids, :2])
        return shift / C.PIXEL_SIZE, angle
