"""FOTS-style marker motion as pure functions, and drawing the dots into the image.

Marker positions are (col, row) pixels. A marker's displacement is the sum of three fields
(FOTS, Zhao et al. 2024):

- **dilation**: the gel bulges away from a press. FOTS moves a marker m by
  sum_i h_i (m - c_i) exp(-|m - c_i|^2 / 2 s^2) over pressed pixels c_i of indentation h_i; that
  sum is proportional to -grad(G_s * h)(m), so we take the slope of the Gaussian-blurred
  indentation (cheap with OpenCV) times a gain. It points away from the press, grows with the
  indentation and vanishes a few s outside the contact.
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


def dilation_field(indentation_px: np.ndarray, mask: np.ndarray, sigma: float = C.DILATION_SIGMA,
                   gain: float = C.DILATION_GAIN) -> tuple[np.ndarray, tuple[int, int]]:
    """FOTS dilation displacement (2, h, w) px = -gain * grad(G_sigma * indentation) over the
    contact's bounding box grown by 4 sigma (zero beyond), and that box's (row, col) origin."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    m = int(np.ceil(4 * sigma))
    H, W = mask.shape
    r0, c0 = max(0, rows[0] - m), max(0, cols[0] - m)
    r1, c1 = min(H, rows[-1] + m + 1), min(W, cols[-1] + m + 1)
    k = 2 * int(np.ceil(3 * sigma)) + 1
    smooth = cv2.GaussianBlur(np.asarray(indentation_px[r0:r1, c0:c1], np.float32), (k, k), sigma,
                              borderType=cv2.BORDER_CONSTANT)
    gy, gx = np.gradient(smooth)
    return -gain * np.stack([gx, gy]), (r0, c0)


def marker_displacements(initial_xy: np.ndarray, penetration: np.ndarray, shear_px=(0.0, 0.0),
                         twist_rad: float = 0.0, *, centre=None, pixel: float = C.PIXEL_SIZE,
                         threshold: float = C.CONTACT_THRESHOLD, dilation_gain: float = C.DILATION_GAIN,
                         dilation_sigma: float = C.DILATION_SIGMA, decay: float = C.SHEAR_DECAY) -> np.ndarray:
    """Current marker positions (M, 2) px.

    ``initial_xy``: (M, 2) rest positions (col, row); ``penetration``: (H, W) map in metres;
    ``shear_px``: (2,) patch translation since contact onset (cols, rows); ``twist_rad``: patch
    rotation since onset (from +col towards +row) about ``centre`` (col, row; default: the
    contact centroid). Without contact the markers are at rest (a copy of ``initial_xy``).
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
    # Dilation, sampled inside its box only (zero outside by construction).
    field, (r0, c0) = dilation_field(pen / pixel, mask, dilation_sigma, dilation_gain)
    local = xy - (c0, r0)
    h, w = field.shape[1:]
    inside = (local[:, 0] >= 0) & (local[:, 0] <= w - 1) & (local[:, 1] >= 0) & (local[:, 1] <= h - 1)
    out = xy.copy()
    if inside.any():
        out[inside, 0] += sample_bilinear(field[0], local[inside])
        out[inside, 1] += sample_bilinear(field[1], local[inside])
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
