"""FOTS-style marker motion as pure functions, and drawing the dots into the image.

Marker positions are (col, row) pixels. A marker's displacement is the sum of three fields
(FOTS, Zhao et al. 2024):

- **dilation**: the gel is nearly incompressible silicone bonded to acrylic, so the volume an
  object presses in must flow out sideways through the layer. Mass conservation over the layer
  (thickness h) with a potential flow gives the mean lateral displacement
  u(m) = 1 / (2 pi h) sum_j V_j (m - c_j) / |m - c_j|^2 over the pressed cells (volume V_j at
  c_j): outward from the press, V / (2 pi h r) far from it, so it grows with the pressed
  volume, i.e. with the force (V = F / K on the elastic foundation, :mod:`.gel`). The flow is
  parabolic across the thickness (no slip on the acrylic, a free surface), so the surface,
  where the markers are printed, moves 1.5x the mean. Written by hand: FOTS's dilation is a
  fitted Gaussian of the local slope, which a wide shallow press (a soft object on a stiffer
  gel) barely moves and which is not monotone in the force; this has no fitted constant.
- **shear**: the contact patch's tangential translation since contact onset, carried fully by
  markers under the contact and decaying as exp(-distance / decay) outside it;
- **twist**: the patch's rotation since onset about the contact centre, with the same decay.

Angles follow the image axes: a positive twist turns +col towards +row, i.e. a right-handed
rotation about the pad's +z (the axis pointing away from the camera), which looks clockwise
on screen.
"""

from __future__ import annotations

import cv2
import numpy as np

from . import constants as C

# Shear/twist weights below exp(-8) (3e-4) are set to zero, so markers far from the contact stay
# exactly put instead of drifting by a round-off-sized amount.
_DECAY_CUTOFF = 8.0


def marker_grid(cols: int = C.MARKER_COLS, rows: int = C.MARKER_ROWS, width: int = C.IMAGE_WIDTH,
                height: int = C.IMAGE_HEIGHT) -> np.ndarray:
    """Initial marker positions (cols * rows, 2) as (col, row) px: a uniform grid with half-spacing
    margins, row-major (all columns of the top row first). Symmetric about the image centre."""
    xs = (np.arange(cols) + 0.5) * width / cols - 0.5
    ys = (np.arange(rows) + 0.5) * height / rows - 0.5
    X, Y = np.meshgrid(xs, ys)
    return np.stack([X.ravel(), Y.ravel()], axis=1)


def sample_bilinear(field: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear samples (M,) of a (H, W) field at (col, row) positions (M, 2); edges replicated."""
    xy = np.asarray(xy, np.float32)
    out = cv2.remap(np.asarray(field, np.float32), xy[None, :, 0], xy[None, :, 1], cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out[0].astype(np.float64)


def contact_weight(mask: np.ndarray, xy: np.ndarray, decay: float = C.SHEAR_DECAY) -> np.ndarray:
    """Weight (M,) of the patch motion that the gel carries to the points ``xy`` (M, 2) px: 1 inside
    the contact, exp(-d / decay) at distance d (px) outside it, 0 beyond 8 decay lengths or without
    contact. Distances: OpenCV's 5x5 chamfer transform (within 2 % of Euclidean), sampled bilinearly."""
    xy = np.asarray(xy, np.float64)
    if not mask.any():
        return np.zeros(len(xy))
    dist = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
    d = sample_bilinear(dist, xy)
    return np.where(d > _DECAY_CUTOFF * decay, 0.0, np.exp(-d / decay))


def pooled_indentation(indentation: np.ndarray, pool: int = C.FLOW_POOL) -> np.ndarray:
    """The indentation (H, W) summed over ``pool`` x ``pool`` cells (zero-padded at the far edges),
    flattened row-major: each cell's pressed volume in metres x pixels."""
    ind = np.asarray(indentation, np.float64)
    ind = np.pad(ind, ((0, -ind.shape[0] % pool), (0, -ind.shape[1] % pool)))
    return ind.reshape(ind.shape[0] // pool, pool, ind.shape[1] // pool, pool).sum(axis=(1, 3)).ravel()


def flow_matrix(xy: np.ndarray, shape: tuple[int, int], thickness: float = C.GEL_THICKNESS,
                pool: int = C.FLOW_POOL, surface_factor: float = C.FLOW_SURFACE_FACTOR) -> np.ndarray:
    """(M, 2, cells): the surface displacement (px) at each point ``xy`` (M, 2) (col, row) px per unit
    of pooled volume in each cell of an indentation map of ``shape`` (module docstring). Depends
    on the points and the grid only, so a sensor builds it once. The kernel is softened by half a
    cell so that a point on a pressed cell gets a finite push."""
    xy = np.asarray(xy, np.float64)
    rows = (np.arange(-(-shape[0] // pool)) + 0.5) * pool - 0.5
    cols = (np.arange(-(-shape[1] // pool)) + 0.5) * pool - 0.5
    cy, cx = (a.ravel() for a in np.meshgrid(rows, cols, indexing="ij"))
    dx, dy = xy[:, 0:1] - cx, xy[:, 1:2] - cy  # (M, cells) px
    # A cell's volume V = vol pixel^2 moves a point at r by V / (2 pi h r) metres: in pixels,
    # vol / (2 pi h r_px), the pixel size cancels.
    k = surface_factor / (2 * np.pi * thickness) / (dx * dx + dy * dy + (0.5 * pool) ** 2)
    return np.stack([k * dx, k * dy], axis=1)


def gel_flow(indentation: np.ndarray, xy: np.ndarray, thickness: float = C.GEL_THICKNESS,
             pool: int = C.FLOW_POOL, matrix: np.ndarray | None = None) -> np.ndarray:
    """In-plane displacement (M, 2) px of the gel's surface at ``xy`` (M, 2) (col, row) px: the
    volume pressed in by ``indentation`` ((H, W) metres, on the same pixels) flowing out through a
    layer of ``thickness`` (module docstring). ``matrix``: :func:`flow_matrix` of these points, if
    built already."""
    if matrix is None:
        matrix = flow_matrix(xy, np.shape(indentation), thickness, pool)
    return matrix @ pooled_indentation(indentation, pool)


def marker_displacements(initial_xy: np.ndarray, penetration: np.ndarray, shear_px=(0.0, 0.0),
                         twist_rad: float = 0.0, *, centre=None,
                         threshold: float = C.CONTACT_THRESHOLD, thickness: float = C.GEL_THICKNESS,
                         pool: int = C.FLOW_POOL, decay: float = C.SHEAR_DECAY,
                         flow: np.ndarray | None = None) -> np.ndarray:
    """Current marker positions (M, 2) px.

    ``initial_xy``: (M, 2) rest positions (col, row); ``penetration``: (H, W) map in metres;
    ``shear_px``: (2,) patch translation since contact onset (cols, rows); ``twist_rad``: patch
    rotation since onset (from +col towards +row) about ``centre`` (col, row; default: the
    contact centroid); ``flow``: :func:`flow_matrix` of ``initial_xy`` on this map's grid, if
    built already. Without contact the markers are at rest (a copy of ``initial_xy``).
    """
    xy = np.asarray(initial_xy, np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"initial_xy must have shape (M, 2), got {xy.shape}")
    pen = np.asarray(penetration)
    if pen.ndim != 2:
        raise ValueError(f"penetration must be a (H, W) map, got shape {pen.shape}")
    shear = np.asarray(shear_px, np.float64).reshape(-1)
    if shear.shape != (2,) or not np.all(np.isfinite(shear)) or not np.isfinite(twist_rad):
        raise ValueError(f"shear_px must be 2 finite numbers and twist_rad finite, got {shear_px!r}, {twist_rad!r}")
    mask = pen > threshold
    if not mask.any():
        return xy.copy()
    out = xy + gel_flow(pen, xy, thickness, pool, flow)
    if not shear.any() and twist_rad == 0.0:
        return out
    weight = contact_weight(mask, xy, decay)[:, None]
    if centre is None:
        rows, cols = np.nonzero(mask)
        centre = (cols.mean(), rows.mean())
    c, s = np.cos(twist_rad), np.sin(twist_rad)
    rel = xy - np.asarray(centre, np.float64)
    rotated = rel @ np.array([[c, s], [-s, c]])  # row vectors: (x c - y s, x s + y c)
    return out + weight * (shear[None] + rotated - rel)


def draw_markers(image: np.ndarray, xy: np.ndarray, radius: float = C.MARKER_RADIUS,
                 color: tuple[int, int, int] = C.MARKER_COLOR) -> np.ndarray:
    """A copy of ``image`` with dark anti-aliased dots at the sub-pixel positions ``xy`` (M, 2),
    as a Mini's printed markers look through the gel."""
    out = np.array(image, np.uint8, copy=True)
    scale = 1 << C.MARKER_DRAW_SHIFT
    pts = np.rint(np.asarray(xy, np.float64) * scale).astype(np.int64)
    r = int(round(radius * scale))
    for x, y in pts:
        cv2.circle(out, (int(x), int(y)), r, color, -1, cv2.LINE_AA, C.MARKER_DRAW_SHIFT)
    return out
