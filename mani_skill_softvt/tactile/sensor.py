"""The per-finger GelSight Mini sensor: contact mesh + pad pose in, tactile image + markers out.

Pad frame (see :mod:`.geometry`): origin at the centre of the gel surface, +z the gel's outward
normal pointing towards the grasped object, x along image columns (left to right), y along
image rows (top to bottom). It is right-handed and is the frame of a camera inside the finger
looking out through the gel (x right, y down, z forward), so the image shows the contact as
that camera sees it.

Left/right mirroring. The two fingers' cameras face each other. Both are mounted with the same
"up" (image y along the same hand direction), so a contact point towards +x of the hand shows
on the right of the left finger's image and on the left of the right finger's image: the right
image is the left one flipped horizontally. In frames: with +z of each pad pointing at the
other finger, the left pad's x is the hand's x and the right pad's x is the hand's -x
(:func:`finger_pad_frame`, :meth:`TactileSensor.pad_pose`); both then share y = z x x. The
sensor itself renders whatever pad pose it is given: mirroring lives in the pad frame, so it
is never applied twice.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..contracts.observations import SIDES
from . import constants as C
from ..physics.transforms import planar_rigid_fit
from .config import DEFAULT_TACTILE, TactileConfig
from .gel import (balanced_indentation, footprint_mask, foundation_stiffness, geometric_indentation,
                  pressure_indentation)
from .geometry import gap_from_triangles, to_pixels, validate_mesh
from .markers import draw_markers, flow_matrix, marker_displacements, marker_grid
from .optics import load_optics, render_image

# Sign of the pad's x axis along the hand's x axis: the right camera is the mirror of the left.
MIRROR_SIGN = {"left": 1.0, "right": -1.0}


@dataclass
class TactileFrame:
    """One finger's GelSight frame."""

    image: np.ndarray  # (240, 320, 3) uint8 RGB, markers drawn
    marker_initial: np.ndarray  # (99, 2) float32 (col, row) px, rest positions
    marker_current: np.ndarray  # (99, 2) float32 (col, row) px
    depth: np.ndarray  # (240, 320) float64 gel indentation (m), at most the gel thickness
    normal_force: float | None = None  # N pressing the pad (None: the geometry was prescribed)
    sink: float = 0.0  # m: the rigid-object gel's common sink depth d (tactile.gel), else 0
    contact: np.ndarray | None = None  # (240, 320) bool: where the object presses the gel at all

    def __post_init__(self):
        if self.contact is None:
            self.contact = self.depth > 0.0


def pad_frame(origin: np.ndarray, normal: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """4x4 world pose of a pad frame: origin at ``origin``, +z along ``normal``, +x along ``x_hint``
    made orthogonal to it, y = z x x (right-handed)."""
    z = np.asarray(normal, np.float64)
    xh = np.asarray(x_hint, np.float64)
    if z.shape != (3,) or xh.shape != (3,) or np.asarray(origin).shape != (3,):
        raise ValueError("origin, normal and x_hint must be 3-vectors")
    z = z / np.linalg.norm(z)
    x = xh - np.dot(xh, z) * z
    n = np.linalg.norm(x)
    if not n > 1e-9:
        raise ValueError("x_hint must not be parallel to the pad normal")
    x /= n
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, np.cross(z, x), z, origin
    return m


def finger_pad_frame(side: str, origin: np.ndarray, normal: np.ndarray, hand_x: np.ndarray) -> np.ndarray:
    """Pad pose of the ``side`` finger whose gel centre is ``origin`` and faces along ``normal``:
    x along ``hand_x`` for the left finger and along ``-hand_x`` for the right one, so the right
    image is the horizontal mirror of the left (module docstring)."""
    if side not in SIDES:
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    return pad_frame(origin, normal, MIRROR_SIGN[side] * np.asarray(hand_x, np.float64))


def world_to_pad(vertices_world: np.ndarray, pad_pose_world: np.ndarray) -> np.ndarray:
    """World points (N, 3) expressed in the pad frame whose 4x4 world pose is given."""
    m = np.asarray(pad_pose_world, np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"pad_pose_world must be a 4x4 matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError("pad_pose_world contains NaN or inf")
    rot = m[:3, :3]
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
        raise ValueError("pad_pose_world's rotation block must be a proper rotation")
    return (np.asarray(vertices_world, np.float64) - m[:3, 3]) @ rot


class TactileSensor:
    """One GelSight Mini on one finger. Call :meth:`reset` at episode start, :meth:`render` per frame.

    Between renders it remembers where each object vertex touching the gel was when it began to
    touch (the gel under it is stuck to it since then), to turn the patch's in-plane motion since
    then into marker shear and twist; a vertex that leaves the gel releases it, and everything is
    forgotten when contact is lost, on :meth:`reset`, or when the mesh's vertex count changes.
    """

    def __init__(self, side: str = "left", pad_half_extents=None, config: TactileConfig = DEFAULT_TACTILE):
        if side not in SIDES:
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        if not isinstance(config, TactileConfig):
            raise TypeError(f"config must be a TactileConfig (tactile.config), got {config!r}")
        self.side = side
        self.config = config  # every field is read below (the gel, its grid, the markers)
        self.optics = load_optics()
        self.marker_initial = marker_grid()
        self.background_frame = draw_markers(self.optics.background, self.marker_initial, config.marker_radius)
        self.stiffness = foundation_stiffness(config.gel_modulus, config.gel_thickness, config.gel_poisson)
        # The gel grid: the field of view at 1/downsample resolution, with rows added above and
        # below where the pad is longer than the view (the force is carried by the whole pad).
        downsample = config.grid_downsample
        self.downsample = downsample
        self.grid_pixel = C.PIXEL_SIZE * downsample
        self.grid_width, self.view_rows = C.IMAGE_WIDTH // downsample, C.IMAGE_HEIGHT // downsample
        half = (C.FOV_WIDTH / 2, C.FOV_HEIGHT / 2) if pad_half_extents is None else tuple(map(float, pad_half_extents))
        self.half_extents = half
        # The gel in view: the pad cut to the field of view.
        self.view_half_extents = (min(half[0], C.FOV_WIDTH / 2), min(half[1], C.FOV_HEIGHT / 2))
        # Marker rest positions in gel-grid pixels (pixel centres map as (x + 0.5) / k - 0.5).
        self.marker_grid_xy = (self.marker_initial + 0.5) / downsample - 0.5
        self.marker_flow = flow_matrix(self.marker_grid_xy, (self.view_rows, self.grid_width), config.gel_thickness,
                                       config.flow_pool, config.flow_surface_factor)
        self.extra_rows = max(0, int(np.ceil(half[1] / self.grid_pixel - self.view_rows / 2)))
        self.footprint = footprint_mask(self.view_rows + 2 * self.extra_rows, self.grid_width, self.grid_pixel, half)
        self.reset()

    def reset(self) -> None:
        """Forget the contact (start of an episode)."""
        self._anchors: np.ndarray | None = None  # (vertices, 2) pad xy where each touched; NaN: not touching

    def pad_pose(self, origin: np.ndarray, normal: np.ndarray, hand_x: np.ndarray) -> np.ndarray:
        """This finger's pad pose (see :func:`finger_pad_frame`)."""
        return finger_pad_frame(self.side, origin, normal, hand_x)

    def render(self, vertices_world: np.ndarray, faces: np.ndarray, pad_pose_world: np.ndarray,
               normal_force: float | None = None, deformable: bool = True) -> TactileFrame:
        """Frame for the object surface (world vertices (N, 3), triangles (F, 3)) seen by the pad
        whose 4x4 world pose (pad frame -> world) is ``pad_pose_world``; ``normal_force`` and
        ``deformable`` as in :meth:`indentation`."""
        v, f = validate_mesh(vertices_world, faces, "vertices_world")
        return self.render_local(world_to_pad(v, pad_pose_world), f, normal_force, deformable)

    def indentation(self, vertices_pad: np.ndarray, faces: np.ndarray, normal_force: float | None = None,
                    deformable: bool = True) -> tuple[np.ndarray, float]:
        """Gel indentation (m) on the gel grid over the field of view, and the rigid-object sink
        depth d (0 otherwise). The gel models are in :mod:`.gel`:

        - ``normal_force`` None: the surface's pose is prescribed (geometric indentation);
        - a force (N) and ``deformable``: an FEM surface against the simulator's rigid pad, the
          gel sinks with the contact pressure (pressure indentation);
        - a force and not ``deformable``: a rigid surface, the gel alone conforms (force balance).
        """
        v, f = validate_mesh(vertices_pad, faces, "vertices_pad")
        # Only a rigid surface can load the gel where it does not reach the plane (up to the sink
        # depth, at most the travel); the other models need the overlap alone, far fewer pixels.
        travel = self.config.gel_thickness
        reach = travel if normal_force is not None and not deformable else 0.0
        gap = gap_from_triangles(v, f, reach, self.grid_width, len(self.footprint), self.grid_pixel)
        gap[~self.footprint] = np.inf
        sink = 0.0
        if normal_force is None:
            ind = geometric_indentation(gap, travel)
        elif deformable:
            # Between nodes the linear surface can dip further than any node does (a triangle
            # spanning the pad's edge to a node that wraps around it): no deeper than the nodes.
            hx, hy = self.half_extents
            on_pad = (np.abs(v[:, 0]) <= hx) & (np.abs(v[:, 1]) <= hy)
            cap = float(max(0.0, -v[on_pad, 2].min())) if on_pad.any() else 0.0
            ind = pressure_indentation(gap, float(normal_force), self.stiffness, self.grid_pixel ** 2, cap, travel)
        else:
            ind, sink = balanced_indentation(gap, float(normal_force), self.stiffness, self.grid_pixel ** 2, travel)
        return ind[self.extra_rows:self.extra_rows + self.view_rows], sink

    def render_local(self, vertices_pad: np.ndarray, faces: np.ndarray, normal_force: float | None = None,
                     deformable: bool = True) -> TactileFrame:
        """Frame for a surface already expressed in the pad frame (see :meth:`indentation`)."""
        v, f = validate_mesh(vertices_pad, faces, "vertices_pad")
        grid, sink = self.indentation(v, f, normal_force, deformable)
        initial = self.marker_initial.astype(np.float32)
        if not (grid > 0.0).any():
            self._anchors = None
            return TactileFrame(self.background_frame.copy(), initial, initial.copy(),
                                np.zeros((C.IMAGE_HEIGHT, C.IMAGE_WIDTH)), normal_force, sink)
        depth, touching = grid, grid > 0.0
        if self.downsample > 1:
            depth = cv2.resize(grid, (C.IMAGE_WIDTH, C.IMAGE_HEIGHT), interpolation=cv2.INTER_LINEAR)
            touching = cv2.resize(touching.view(np.uint8), (C.IMAGE_WIDTH, C.IMAGE_HEIGHT),
                                  interpolation=cv2.INTER_NEAREST).astype(bool)
        shear_px, twist, centre = self._patch_motion(v, f, sink)  # 0 but for a rigid surface
        # The marker field on the gel grid (its fields are smooth at that scale): positions and
        # lengths scale by 1 / downsample.
        k = self.downsample
        current = k * marker_displacements(
            self.marker_grid_xy, grid, np.asarray(shear_px) / k, twist,
            centre=None if centre is None else (np.asarray(centre) + 0.5) / k - 0.5,
            thickness=self.config.gel_thickness, pool=self.config.flow_pool, decay=self.config.shear_decay / k,
            flow=self.marker_flow, threshold=0.0)  # the whole patch drags the gel, not only its deep part
        current = current - k * self.marker_grid_xy + self.marker_initial  # exact rest positions kept
        image = draw_markers(render_image(grid, self.optics), current, self.config.marker_radius)
        return TactileFrame(image, initial, current.astype(np.float32), depth, normal_force, sink, touching)

    def _contact_vertices(self, v: np.ndarray, f: np.ndarray, reach: float) -> np.ndarray:
        """Ids of the vertices of triangles that reach into the gel (closer than ``reach`` to its
        plane) inside the field of view (the material patch that grips the gel; a triangle's
        corners cover contacts between vertices)."""
        tri_z = v[f, 2]
        hit = (tri_z.min(axis=1) < reach) & (tri_z.max(axis=1) > -C.BEHIND_PAD_CULL)
        ids = np.unique(f[hit])
        in_view = (np.abs(v[ids, 0]) <= C.FOV_WIDTH / 2) & (np.abs(v[ids, 1]) <= C.FOV_HEIGHT / 2)
        touching = in_view & (v[ids, 2] < reach + C.CONTACT_THRESHOLD)
        # The vertices that touch are the material that grips the gel; a triangle's other corners
        # can lie millimetres off the pad and move with the object's rotation, not its contact.
        for keep in (touching, in_view):
            if keep.any():
                return ids[keep]
        return ids

    def _patch_motion(self, v: np.ndarray, f: np.ndarray, reach: float) -> tuple[np.ndarray, float, np.ndarray | None]:
        """Shear (px, (col, row)), twist (rad) and rotation centre (px) of the contact patch: a 2-D
        rigid (Kabsch) fit of the in-plane motion of the touching vertices, each since it began to
        touch: a patch that grows, creeps or slips on the pad drags the gel under all of it, not
        only under the two or three vertices that touched first."""
        ids = self._contact_vertices(v, f, reach)
        if self._anchors is None or len(self._anchors) != len(v):
            self._anchors = np.full((len(v), 2), np.nan)
        anchors = self._anchors
        released = np.ones(len(v), bool)
        released[ids] = False
        anchors[released] = np.nan
        new = ids[np.isnan(anchors[ids, 0])]
        anchors[new] = v[new, :2]
        if len(new) == len(ids):  # contact onset: nothing has moved yet
            return np.zeros(2), 0.0, None
        angle, shift = planar_rigid_fit(anchors[ids], v[ids, :2])
        centre = to_pixels(anchors[ids].mean(axis=0))  # rotation centre: where the patch was
        return shift / C.PIXEL_SIZE, angle, centre
