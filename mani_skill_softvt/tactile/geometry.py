"""Contact geometry as pure functions: object triangles in the pad frame -> gel penetration map.

Pad frame (the convention every function here uses):

- origin at the centre of the gel surface; the undeformed gel surface is the plane z = 0;
- +z is the gel's outward normal, pointing from the sensor towards the object (the sensor's
  camera sits behind the gel and looks along +z);
- x runs along image columns (left to right), y along image rows (top to bottom), so the pad
  frame is also the camera frame of the image (x right, y down, z forward).

An object that merely touches the gel lies in z >= 0. Where its surface lies at z < 0 it has
pushed the gel in: the **penetration** at a pixel is ``max(0, -z_surface)`` of the object
surface closest to the camera (lowest z) along that pixel's ray, clamped to
``[0, GEL_THICKNESS]``. Pixel (col, row) looks along the ray through
``x = (col + 0.5 - W / 2) * pixel``, ``y = (row + 0.5 - H / 2) * pixel`` (orthographic: the gel
is ~2 mm thick, so the camera's perspective over the indentation is negligible).
"""

from __future__ import annotations

import cv2
import numpy as np

from . import constants as C
from .gel import geometric_indentation

# Barycentric slack so pixel centres exactly on a shared edge are painted by both triangles
# (no cracks between neighbours); the z-buffer keeps the deeper one.
_EDGE_EPS = 1e-9
# Projected (doubled) triangle areas below this (m^2) are edge-on to the camera: nothing to paint.
_MIN_DET = 1e-24


def pixel_centers(width: int = C.IMAGE_WIDTH, height: int = C.IMAGE_HEIGHT,
                  pixel: float = C.PIXEL_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """Pad-frame x of each column's and y of each row's pixel centre (m)."""
    xs = (np.arange(width) + 0.5 - width / 2) * pixel
    ys = (np.arange(height) + 0.5 - height / 2) * pixel
    return xs, ys


def to_pixels(xy: np.ndarray, width: int = C.IMAGE_WIDTH, height: int = C.IMAGE_HEIGHT,
              pixel: float = C.PIXEL_SIZE) -> np.ndarray:
    """Pad-frame xy (m), shape (..., 2) -> continuous pixel coordinates (col, row)."""
    xy = np.asarray(xy, np.float64)
    return np.stack([xy[..., 0] / pixel + width / 2 - 0.5, xy[..., 1] / pixel + height / 2 - 0.5], axis=-1)


def validate_mesh(vertices: np.ndarray, faces: np.ndarray, name: str = "vertices") -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) finite float64 vertices and (F, 3) int64 faces indexing them, or a ValueError saying
    what is wrong."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got shape {v.shape}")
    if f.size == 0:
        return v, np.zeros((0, 3), np.int64)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got shape {f.shape}")
    if not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be integer vertex indices, got dtype {f.dtype}")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"faces index vertices {f.min()}..{f.max()} but there are only {len(v)} {name}")
    if not np.all(np.isfinite(v)):
        bad = int((~np.isfinite(v)).any(axis=1).sum())
        raise ValueError(f"{name} contain NaN or inf ({bad} of {len(v)} rows)")
    return v, f.astype(np.int64, copy=False)


def heightmap_from_triangles(vertices: np.ndarray, faces: np.ndarray, width: int = C.IMAGE_WIDTH,
                             height: int = C.IMAGE_HEIGHT, pixel: float = C.PIXEL_SIZE,
                             max_penetration: float = C.GEL_THICKNESS) -> np.ndarray:
    """Penetration depth map (H, W) in metres of a triangle mesh given in the pad frame.

    The gap map (:func:`gap_from_triangles`) of what reaches past the gel plane, as the gel
    takes it when the pose is prescribed: ``clip(-z_min, 0, max_penetration)``.
    """
    return geometric_indentation(gap_from_triangles(vertices, faces, 0.0, width, height, pixel), max_penetration)


def gap_from_triangles(vertices: np.ndarray, faces: np.ndarray, reach: float, width: int = C.IMAGE_WIDTH,
                       height: int = C.IMAGE_HEIGHT, pixel: float = C.PIXEL_SIZE) -> np.ndarray:
    """Gap map (H, W) in metres: the height z of the mesh surface closest to the camera along each
    pixel's ray, where it lies below ``reach`` (negative: past the gel plane), +inf elsewhere.

    What the force-balanced gel (:mod:`.gel`) needs: not only where the object crosses the gel
    plane but how far each point of it is from touching, up to the gel's travel.
    """
    v, f = validate_mesh(vertices, faces)
    shifted = v - [0.0, 0.0, reach]  # the z-buffer keeps max(-z) > 0: everything below ``reach``
    depth = np.zeros((height, width))
    if len(f):
        tri = shifted[f]
        lo = np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])
        hi = np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])
        half_w, half_h = width / 2 * pixel, height / 2 * pixel
        cand = (lo[:, 2] < 0.0) & (hi[:, 2] > -C.BEHIND_PAD_CULL - reach) & (hi[:, 0] >= -half_w) \
            & (lo[:, 0] <= half_w) & (hi[:, 1] >= -half_h) & (lo[:, 1] <= half_h)
        if cand.any():
            _zbuffer(tri[cand], lo[cand], hi[cand], depth, pixel)
    gap = reach - depth
    gap[depth <= 0.0] = np.inf
    return gap


def _zbuffer(tri: np.ndarray, lo: np.ndarray, hi: np.ndarray, depth: np.ndarray, pixel: float) -> None:
    """Write max(-z) of the triangles (T, 3, 3) (with their xyz bounds lo, hi (T, 3)) into
    ``depth`` at the pixel centres they cover, vectorised over all (triangle, covered pixel) pairs.
    Barycentric coordinates and the penetration are affine in (col, row), so each triangle is
    reduced to 9 coefficients, each of its rows to one column span, each pixel to a multiply-add."""
    height, width = depth.shape
    off_u, off_w = width / 2 - 0.5, height / 2 - 0.5  # pixel centres sit at integer (col, row)
    u = tri[:, :, 0] / pixel + off_u
    w = tri[:, :, 1] / pixel + off_w
    z = tri[:, :, 2]
    u0, u1, u2, w0, w1, w2 = u[:, 0], u[:, 1], u[:, 2], w[:, 0], w[:, 1], w[:, 2]
    det = (w1 - w2) * (u0 - u2) + (u2 - u1) * (w0 - w2)
    ok = np.abs(det) > _MIN_DET / (pixel * pixel)
    if not ok.all():
        u0, u1, u2, w0, w1, w2, z, det, lo, hi = (a[ok] for a in (u0, u1, u2, w0, w1, w2, z, det, lo, hi))
    # a(col, row) = a_u col + a_w row + a_0 (and b likewise); c = 1 - a - b.
    a_u, a_w = (w1 - w2) / det, (u2 - u1) / det
    b_u, b_w = (w2 - w0) / det, (u0 - u2) / det
    a_0 = -(a_u * u2 + a_w * w2)
    b_0 = -(b_u * u2 + b_w * w2)
    # Penetration -z = -(a z0 + b z1 + c z2) = -(z2 + a (z0 - z2) + b (z1 - z2)).
    dz0, dz1 = z[:, 0] - z[:, 2], z[:, 1] - z[:, 2]
    p_u = -(a_u * dz0 + b_u * dz1)
    p_w = -(a_w * dz0 + b_w * dz1)
    p_0 = -(z[:, 2] + a_0 * dz0 + b_0 * dz1)
    # Scanlines: for each (triangle, row) the three conditions a >= 0, b >= 0, a + b <= 1 are
    # linear in col, so the covered pixels are one column span; only those are evaluated.
    r_lo = np.maximum(np.ceil(lo[:, 1] / pixel + off_w - _EDGE_EPS), 0).astype(np.int64)
    r_hi = np.minimum(np.floor(hi[:, 1] / pixel + off_w + _EDGE_EPS), height - 1).astype(np.int64)
    c_lo_t = np.maximum(np.ceil(lo[:, 0] / pixel + off_u - _EDGE_EPS), 0).astype(np.int64)
    c_hi_t = np.minimum(np.floor(hi[:, 0] / pixel + off_u + _EDGE_EPS), width - 1).astype(np.int64)
    nrows = np.maximum(r_hi - r_lo + 1, 0)
    t = np.repeat(np.arange(len(nrows)), nrows)
    if len(t) == 0:
        return
    row = (r_lo[t] + np.arange(len(t)) - np.repeat(np.cumsum(nrows) - nrows, nrows)).astype(np.float64)
    c_min = c_lo_t[t].astype(np.float64)
    c_max = c_hi_t[t].astype(np.float64)
    # Each condition k_u col + k_w row + k_0 >= -eps bounds col from one side.
    for k_u, k_0 in ((a_u[t], a_w[t] * row + a_0[t]), (b_u[t], b_w[t] * row + b_0[t]),
                     (-(a_u + b_u)[t], 1.0 - (a_w + b_w)[t] * row - (a_0 + b_0)[t])):
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = (-_EDGE_EPS - k_0) / k_u
        pos, neg = k_u > 0, k_u < 0
        c_min = np.where(pos, np.maximum(c_min, np.ceil(bound - 1e-9)), c_min)
        c_max = np.where(neg, np.minimum(c_max, np.floor(bound + 1e-9)), c_max)
        c_max = np.where((k_u == 0) & (k_0 < -_EDGE_EPS), -1.0, c_max)  # row entirely outside
    ncols = np.maximum(c_max - c_min + 1, 0).astype(np.int64)
    total = int(ncols.sum())
    if total == 0:
        return
    span = np.repeat(np.arange(len(ncols)), ncols)
    col = c_min[span] + (np.arange(total) - np.repeat(np.cumsum(ncols) - ncols, ncols))
    ts, rows = t[span], row[span]
    pen = p_u[ts] * col + p_w[ts] * rows + p_0[ts]
    keep = pen > 0.0
    np.maximum.at(depth.reshape(-1), rows[keep].astype(np.int64) * width + col[keep].astype(np.int64), pen[keep])


def contact_mask(height: np.ndarray, threshold: float = C.CONTACT_THRESHOLD) -> np.ndarray:
    """Boolean (H, W): pixels where the gel is pushed in by more than ``threshold`` (m)."""
    return np.asarray(height) > threshold


def contact_area(height: np.ndarray, pixel: float = C.PIXEL_SIZE, threshold: float = C.CONTACT_THRESHOLD) -> float:
    """Contact area (m^2): the number of contact pixels times the pixel area."""
    return float(contact_mask(height, threshold).sum() * pixel * pixel)


def contact_centroid(height: np.ndarray, threshold: float = C.CONTACT_THRESHOLD) -> np.ndarray | None:
    """Centroid (col, row) in pixels of the contact patch (unweighted), or None without contact."""
    rows, cols = np.nonzero(contact_mask(height, threshold))
    if len(rows) == 0:
        return None
    return np.array([cols.mean(), rows.mean()])


def _clip_polygon(poly: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Sutherland-Hodgman: the part of a convex polygon (K, D) with ``poly @ normal <= offset``."""
    if len(poly) == 0:
        return poly
    s = poly @ normal - offset
    out = []
    for k in range(len(poly)):
        a, b, sa, sb = poly[k], poly[(k + 1) % len(poly)], s[k], s[(k + 1) % len(poly)]
        if sa <= 0:
            out.append(a)
        if (sa < 0 < sb) or (sb < 0 < sa):
            out.append(a + (b - a) * (sa / (sa - sb)))
    return np.array(out).reshape(-1, poly.shape[1])


def contact_polygons(vertices_pad: np.ndarray, faces: np.ndarray, half_extents) -> list[np.ndarray]:
    """The surface in contact with a flat pad, exactly: each triangle's part at or past the gel
    plane (z <= 0), projected onto it and clipped to the pad rectangle ``half_extents`` (x, y), as
    convex polygons (K, 2) in metres. Polygon clipping, not pixels: the reference the rendered
    patch is checked against (tests, gallery). Polygons of different triangles may overlap in
    projection (a surface folding around the pad's edge): take the union (:func:`polygons_mask`)."""
    v, f = validate_mesh(vertices_pad, faces, "vertices_pad")
    hx, hy = map(float, half_extents)
    tri = v[f]
    near = (tri[:, :, 2].min(axis=1) <= 0.0) & (tri[:, :, 2].max(axis=1) > -C.BEHIND_PAD_CULL)
    out = []
    for t in tri[near]:
        poly = _clip_polygon(t, np.array([0.0, 0.0, 1.0]), 0.0)  # the part with z <= 0
        xy = poly[:, :2]
        for n, o in (((1.0, 0.0), hx), ((-1.0, 0.0), hx), ((0.0, 1.0), hy), ((0.0, -1.0), hy)):
            xy = _clip_polygon(xy, np.array(n), o)
        if len(xy) >= 3:
            out.append(xy)
    return out


def polygon_area(xy: np.ndarray) -> float:
    """Unsigned area of a simple polygon (K, 2) (shoelace)."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def polygons_mask(polygons: list[np.ndarray], width: int = C.IMAGE_WIDTH, height: int = C.IMAGE_HEIGHT,
                  pixel: float = C.PIXEL_SIZE) -> np.ndarray:
    """Boolean (H, W): pixel centres inside any of the pad-frame polygons (OpenCV's scan fill)."""
    mask = np.zeros((height, width), np.uint8)
    shift = 4  # 1/16 px fixed point
    for xy in polygons:
        pts = np.rint(to_pixels(xy, width, height, pixel) * (1 << shift)).astype(np.int32)
        cv2.fillPoly(mask, [pts], 1, cv2.LINE_8, shift)
    return mask.astype(bool)
