"""FOTS-style marker motion as pure functions, and drawing the dots into the image.

A marker moves by the sum of three fields (pixels):
- dilation: the gel bulges away from a press, pushing markers down the slope of the smoothed
  penetration (outwards from the contact, zero far from it);
- shear: the contact patch's tangential translation since contact onset, carried fully by the
  markers under the contact and decaying exponentially with distance outside it;
- twist: the patch's rotation since onset about the contact centroid, with the same decay.
"""

from __future__ import annotations

import cv2
import numpy as np

from . import constants as C


def marker_grid(cols: int = C.MARKER_COLS, rows: int = C.MARKER_ROWS, width: int = C.IMAGE_WIDTH,
                height: int = C.IMAGE_HEIGHT) -> np.ndarray:
    """Initial marker positions (cols*rows, 2) as (col, row) pixels, uniform with half-spacing margins."""
    xs = (np.arange(cols) + 0.5) * width / cols - 0.5
    ys = (np.arange(rows) + 0.5) * height / rows - 0.5
    X, Y = np.meshgrid(xs, ys)
    return np.stack([X.ravel(), Y.ravel()], axis=1)


def _sample(field: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear sample of a (H, W) field at (col, row) positions."""
    m = cv2.remap(field.astype(np.float32), xy[:, 0].astype(np.float32)[None], xy[:, 1].astype(np.float32)[None],
                  cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return m[0].astype(np.float64)


def contact_weight(mask: np.ndarray, decay: float = C.SHEAR_DECAY) -> np.ndarray:
    """1 inside the contact, exp(-distance / decay) outside (pixels)."""
    if not mask.any():
        return np.zeros(mask.shape)
    dist = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
    return np.exp(-dist / decay)


def marker_displacements(initial: np.ndarray, penetration_px: np.ndarray, mask: np.ndarray,
                         shear_px=(0.0, 0.0), twist_rad: float = 0.0, centre=None,
                         dilation_gain: float = C.DILATION_GAIN, dilation_sigma: float = C.DILATION_SIGMA,
                         decay: float = C.SHEAR_DECAY) -> np.ndarray:
    """Current marker positions (M, 2) given the penetration (pixel units) and the patch motion."""
    xy = np.asarray(initial, np.float64)
    if not mask.any():
        return xy.copy()
    # Dilation: slope of the smoothed penetration, computed near the contact only (zero beyond).
    rows, cols = np.nonzero(mask)
    m = int(np.ceil(4 * dilation_sigma))
    r0, c0 = max(0, rows.min() - m), max(0, cols.min() - m)
    r1, c1 = min(mask.shape[0], rows.max() + m + 1), min(mask.shape[1], cols.max() + m + 1)
    smooth = cv2.GaussianBlur(penetration_px[r0:r1, c0:c1].astype(np.float64), (0, 0), dilation_sigma,
                              borderType=cv2.BORDER_CONSTANT)
    gy, gx = np.gradient(smooth)
    slope = np.zeros((2,) + mask.shape)
    slope[0, r0:r1, c0:c1], slope[1, r0:r1, c0:c1] = gx, gy
    dil = -dilation_gain * np.stack([_sample(slope[0], xy), _sample(slope[1], xy)], axis=1)
    w = _sample(contact_weight(mask, decay), xy)[:, None]
    shear = w * np.asarray(shear_px, np.float64)[None]
    if centre is None:
        centre = np.array([cols.mean(), rows.mean()])
    c, s = np.cos(twist_rad), np.sin(twist_rad)
    rel = xy - centre
    twist = w * (rel @ np.array([[c, s], [-s, c]]) - rel)
    return xy + dil + shear + twist


def draw_markers(image: np.ndarray, xy: np.ndarray, radius: float = C.MARKER_RADIUS, color=C.MARKER_COLOR) -> np.ndarray:
    """Dark dots at sub-pixel positions (anti-aliased), as a Mini's printed markers look."""
    out = image.copy()
    shift = 4  # cv2 fixed-point: 1/16 px
    for x, y in np.asarray(xy):
        cv2.circle(out, (int(round(x * 16)), int(round(y * 16))), int(round(radius * 16)), color, -1, cv2.LINE_AA, shift)
    return out
