"""Contact geometry as pure functions: from object triangles to a gel penetration map.

Pad frame convention: origin at the centre of the gel surface, +z the gel's outward normal
(towards the object), x along image columns, y along image rows. The object presses into the
gel where its surface lies below z = 0; the penetration map holds max(0, -z) per pixel,
clamped to what the gel can take.
"""

from __future__ import annotations

import numpy as np

from . import constants as C


def pixel_centers(width: int = C.IMAGE_WIDTH, height: int = C.IMAGE_HEIGHT, pixel: float = C.PIXEL_SIZE):
    """Pad-frame x (per column) and y (per row) of pixel centres (m)."""
    xs = (np.arange(width) + 0.5 - width / 2) * pixel
    ys = (np.arange(height) + 0.5 - height / 2) * pixel
    return xs, ys


def to_pixels(xy: np.ndarray, width: int = C.IMAGE_WIDTH, height: int = C.IMAGE_HEIGHT,
              pixel: float = C.PIXEL_SIZE) -> np.ndarray:
    """Pad-frame xy (m) -> continuous pixel coordinates (col, row)."""
    xy = np.asarray(xy, np.float64)
    return np.stack([xy[..., 0] / pixel + width / 2 - 0.5, xy[..., 1] / pixel + height / 2 - 0.5], axis=-1)


def penetration_map(vertices: np.ndarray, faces: np.ndarray, width: int = C.IMAGE_WIDTH,
                    height: int = C.IMAGE_HEIGHT, pixel: float = C.PIXEL_SIZE,
                    max_penetration: float = C.MAX_PENETRATION) -> np.ndarray:
    """Per-pixel penetration depth (m) of a triangle mesh given in the pad frame.

    Each triangle with a vertex below the gel surface is rasterised over the pixel centres in
    its bounding box; a pixel keeps its deepest (lowest z) surface point.
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (N, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and (f.min() < 0 or f.max() >= len(v))):
        raise ValueError(f"faces must be (F, 3) indices into {len(v)} vertices, got shape {f.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("vertices contain NaN or inf")
    depth = np.zeros((height, width))
    if f.size == 0:
        return depth
    tri = v[f]  # (F, 3, 3)
    half_w, half_h = width / 2 * pixel, height / 2 * pixel
    cand = (tri[:, :, 2].min(axis=1) < 0.0) & (tri[:, :, 0].max(axis=1) >= -half_w) & (tri[:, :, 0].min(axis=1) <= half_w) \
        & (tri[:, :, 1].max(axis=1) >= -half_h) & (tri[:, :, 1].min(axis=1) <= half_h)
    t = tri[cand]
    if len(t):
        _raster_triangles(t, depth, pixel, width, height)
    return np.minimum(depth, max_penetration)


def _raster_triangles(t: np.ndarray, depth: np.ndarray, pixel: float, width: int, height: int) -> None:
    """z-buffer (deepest wins) of triangles over the pixel centres in their bounding boxes, vectorised
    over all (triangle, pixel) pairs."""
    x, y, z = t[:, :, 0], t[:, :, 1], t[:, :, 2]
    det = (y[:, 1] - y[:, 2]) * (x[:, 0] - x[:, 2]) + (x[:, 2] - x[:, 1]) * (y[:, 0] - y[:, 2])
    ok = np.abs(det) > 1e-18  # edge-on triangles have no area to paint
    x, y, z, det = x[ok], y[ok], z[ok], det[ok]
    c_lo = np.clip(np.floor(x.min(1) / pixel + width / 2 - 0.5), 0, width - 1).astype(np.int64)
    c_hi = np.clip(np.ceil(x.max(1) / pixel + width / 2 - 0.5), 0, width - 1).astype(np.int64)
    r_lo = np.clip(np.floor(y.min(1) / pixel + height / 2 - 0.5), 0, height - 1).astype(np.int64)
    r_hi = np.clip(np.ceil(y.max(1) / pixel + height / 2 - 0.5), 0, height - 1).astype(np.int64)
    nc, nr = c_hi - c_lo + 1, r_hi - r_lo + 1
    counts = nc * nr
    tri = np.repeat(np.arange(len(counts)), counts)
    k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    col = c_lo[tri] + k % nc[tri]
    row = r_lo[tri] + k // nc[tri]
    X = (col + 0.5 - width / 2) * pixel
    Y = (row + 0.5 - height / 2) * pixel
    x0, x1, x2 = x[tri, 0], x[tri, 1], x[tri, 2]
    y0, y1, y2 = y[tri, 0], y[tri, 1], y[tri, 2]
    a = ((y1 - y2) * (X - x2) + (x2 - x1) * (Y - y2)) / det[tri]
    b = ((y2 - y0) * (X - x2) + (x0 - x2) * (Y - y2)) / det[tri]
    c = 1.0 - a - b
    inside = (a >= -1e-9) & (b >= -1e-9) & (c >= -1e-9)
    pen = -(a * z[tri, 0] + b * z[tri, 1] + c * z[tri, 2])
    keep = inside & (pen > 0)
    np.maximum.at(depth, (row[keep], col[keep]), pen[keep])


def contact_mask(depth: np.ndarray, threshold: float = C.CONTACT_THRESHOLD) -> np.ndarray:
    return depth > threshold


def contact_area(depth: np.ndarray, pixel: float = C.PIXEL_SIZE, threshold: float = C.CONTACT_THRESHOLD) -> float:
    """Contact area (m^2)."""
    return float(contact_mask(depth, threshold).sum() * pixel * pixel)


def contact_centroid(depth: np.ndarray, threshold: float = C.CONTACT_THRESHOLD) -> np.ndarray | None:
    """Centroid (col, row) in pixels of the contact patch, or None without contact."""
    rows, cols = np.nonzero(contact_mask(depth, threshold))
    if len(rows) == 0:
        return None
    return np.array([cols.mean(), rows.mean()])


def rigid_fit_2d(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray]:
    """Rotation angle and translation of the 2-D rigid motion src -> dst (Kabsch, least squares)."""
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - cs, dst - cd
    angle = float(np.arctan2((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum(), (a * b).sum()))
    return angle, cd - cs
