"""Taxim-style optics: gel spreading, surface normals, polynomial colour lookup, background.

Taxim (Si & Yuan, 2022) models a GelSight image as a background frame plus a colour that
depends on the local surface normal of the deformed gel and on the pixel position. Its
calibration for the GelSight Mini ships with the ``taxim`` pip package (MIT licence) and is
read from the installed package here, never copied into this repository:

- ``polycalib.npz``: ``grad_r``, ``grad_g``, ``grad_b``, each (125, 125, 6). Bin (i, j) holds,
  for surface slopes in magnitude bin i (slope angle over [0, pi/2]) and direction bin j
  (gradient direction over [-pi, pi]), the coefficients of a quadratic in the calibration
  pixel coordinates (x = column, y = row at 640 x 480): ``[x^2, y^2, xy, x, y, 1]``, in 0-255
  intensity units. The channel names are swapped in the file (taxim's own loader stacks
  ``grad_b, grad_g, grad_r`` to get R, G, B), and so do we.
- ``dataPack.npz``: ``f0``, the Mini's frame without contact (480, 640, 3) uint8 in BGR order.
- ``params.json``: 0.0295 mm per pixel at 640 x 480, the gel pyramid sigmas (constants.py).

Unlike taxim we add only the colour *change* a deformation causes (the polynomial at the
deformed normal minus the polynomial at a flat gel) to the raw background, so a frame without
contact is bit-identical to the background; and we ignore taxim's shadow model and the gel's
slight doming (``gelmap.npy``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

import cv2
import numpy as np

from . import constants as C

_BORDER = cv2.BORDER_REFLECT_101  # taxim pads with reflection at the image border


@dataclass(frozen=True)
class OpticsData:
    """The GelSight Mini photometric model at one output resolution."""

    delta_table: np.ndarray  # (bins * bins, 3, 6) float32: per (slope, direction) bin and RGB channel, the quadratic's coefficients minus the flat-gel bin's
    background: np.ndarray  # (H, W, 3) uint8 RGB: the frame without contact
    features: np.ndarray  # (H * W, 6) float32: [x^2, y^2, xy, x, y, 1] of each output pixel in calibration pixels
    pixmm_calib: float  # mm per calibration pixel (params.json)

    @property
    def shape(self) -> tuple[int, int]:
        return self.background.shape[:2]


def calibration_folder():
    """The installed taxim package's GelSight Mini calibration folder (a Traversable)."""
    try:
        return resources.files("taxim") / "calib" / "gelsight_mini"
    except ModuleNotFoundError as e:
        raise ImportError("the tactile sensor needs the 'taxim' package's calibration (pip install taxim==1.4.1)") from e


def bin_width() -> tuple[float, float]:
    """Width (rad) of a slope-magnitude bin over [0, pi/2] and of a direction bin over [-pi, pi]."""
    return 0.5 * np.pi / (C.NUM_BINS - 1), 2.0 * np.pi / (C.NUM_BINS - 1)


def normal_bins(gx: np.ndarray, gy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lookup-table bins (magnitude i, direction j) of surface gradients (dimensionless slopes).

    Magnitude: the slope angle arctan(|grad|) in [0, pi/2). Direction: atan2(gy, gx) of the
    indentation's gradient (gx along columns, gy along rows), in [-pi, pi] -- taxim's convention.
    """
    mag_bw, dir_bw = bin_width()
    mag = np.arctan(np.sqrt(gx * gx + gy * gy))
    ang = np.arctan2(gy, gx)
    i = np.clip((mag / mag_bw).astype(np.int64), 0, C.NUM_BINS - 1)
    j = np.clip(np.floor((ang + np.pi) / dir_bw).astype(np.int64), 0, C.NUM_BINS - 1)
    return i, j


@lru_cache(maxsize=None)
def load_optics(width: int = C.IMAGE_WIDTH, height: int = C.IMAGE_HEIGHT) -> OpticsData:
    """GelSight Mini calibration from the installed ``taxim`` package, at ``width`` x ``height``."""
    with resources.as_file(calibration_folder()) as folder:
        poly = np.load(folder / "polycalib.npz")
        table = np.stack([poly["grad_b"], poly["grad_g"], poly["grad_r"]], axis=-1)  # (bins, bins, 6, RGB)
        with np.load(folder / "dataPack.npz", allow_pickle=True) as pack:
            f0_bgr = np.asarray(pack["f0"])
        sensor = json.loads((folder / "params.json").read_text())["sensor"]
    if table.shape != (C.NUM_BINS, C.NUM_BINS, 6, 3):
        raise ValueError(f"unexpected taxim lookup table shape {table.shape}")
    if (sensor["w"], sensor["h"]) != (C.CALIB_WIDTH, C.CALIB_HEIGHT) or f0_bgr.shape != (C.CALIB_HEIGHT, C.CALIB_WIDTH, 3):
        raise ValueError(f"unexpected taxim calibration resolution {sensor['w']}x{sensor['h']}, f0 {f0_bgr.shape}")
    # INTER_AREA: an exact 2x2 box average at 320 x 240, no aliasing of the background's texture.
    background = cv2.resize(f0_bgr[..., ::-1], (width, height), interpolation=cv2.INTER_AREA)
    # Colour *change* per bin: subtract the flat-gel bin (slope 0, direction atan2(0, 0) = 0).
    fi, fj = normal_bins(np.zeros(1), np.zeros(1))
    delta = (table - table[fi[0], fj[0]]).reshape(C.NUM_BINS * C.NUM_BINS, 6, 3).transpose(0, 2, 1)
    delta = np.ascontiguousarray(delta, dtype=np.float32)  # (bins^2, RGB, 6): one contiguous row per bin
    # Output pixel centres in calibration pixel coordinates (taxim: linspace(0, 640, W, endpoint=False)).
    yy, xx = np.meshgrid(np.arange(height) * (sensor["h"] / height), np.arange(width) * (sensor["w"] / width), indexing="ij")
    x, y = xx.ravel(), yy.ravel()
    features = np.stack([x * x, y * y, x * y, x, y, np.ones_like(x)], axis=1).astype(np.float32)
    return OpticsData(delta, np.ascontiguousarray(background), features, float(sensor["pixmm"]))


def gaussian_blur(img: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur (float32), kernel truncated at GEL_KERNEL_SIGMAS; large sigmas are applied on a
    downsampled copy (box down, linear up; their own small blur is subtracted from sigma^2)."""
    if sigma <= C.GEL_COARSE_SIGMA:
        k = 2 * int(np.ceil(C.GEL_KERNEL_SIGMAS * sigma)) + 1
        return cv2.GaussianBlur(img, (k, k), sigma, borderType=_BORDER)
    f = 4 if sigma >= 4 * C.GEL_COARSE_SIGMA else 2
    h, w = img.shape
    if h % f or w % f:
        f = 1
    if f == 1:
        k = 2 * int(np.ceil(C.GEL_KERNEL_SIGMAS * sigma)) + 1
        return cv2.GaussianBlur(img, (k, k), sigma, borderType=_BORDER)
    small = cv2.resize(img, (w // f, h // f), interpolation=cv2.INTER_AREA)
    # Box-average (f^2 - 1) / 12 and linear-upsample ~f^2 / 6 fine-pixel^2 of variance come for free.
    s = np.sqrt(max(sigma * sigma - (f * f - 1) / 12.0 - f * f / 6.0, 0.25)) / f
    k = 2 * int(np.ceil(C.GEL_KERNEL_SIGMAS * s)) + 1
    small = cv2.GaussianBlur(small, (k, k), s, borderType=_BORDER)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)


def gel_surface(indentation: np.ndarray, pyramid=C.GEL_PYRAMID_SIGMAS, final_sigma: float = C.GEL_FINAL_SIGMA,
                contact_scale: float = C.GEL_CONTACT_SCALE) -> np.ndarray:
    """Indentation of the gel surface (float32, same units as ``indentation``, which is the
    object's penetration per pixel): Taxim's pyramid of Gaussians. The gel is pinned to the object
    where it is pressed deeper than ``contact_scale`` x the maximum, blurred coarse to fine in
    between (the membrane spreading the press over ~1 mm around it), then blurred finely."""
    d = np.asarray(indentation, np.float32)
    peak = float(d.max()) if d.size else 0.0
    if peak <= 0.0:
        return np.zeros_like(d)
    pin = d > contact_scale * peak
    h = d
    for s in pyramid:
        h = gaussian_blur(h, s)
        np.copyto(h, d, where=pin)
    return gaussian_blur(h, final_sigma)


def surface_gradients(height_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Central-difference slopes (gx along columns, gy along rows) of a height field whose values
    are in pixel units (so the slopes are dimensionless)."""
    gy, gx = np.gradient(np.asarray(height_px, np.float32))
    return gx, gy


def _crop_box(mask: np.ndarray, margin: int, align: int = 4) -> tuple[int, int, int, int]:
    """Bounding box (r0, r1, c0, c1) of ``mask`` grown by ``margin``, aligned to ``align`` px
    (so the coarse blurs can downsample it exactly), clipped to the image."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    H, W = mask.shape
    r0 = max(0, (rows[0] - margin) // align * align)
    c0 = max(0, (cols[0] - margin) // align * align)
    r1 = min(H, -(-(rows[-1] + 1 + margin) // align) * align)
    c1 = min(W, -(-(cols[-1] + 1 + margin) // align) * align)
    return r0, r1, c0, c1


# How far the gel relaxes outside the pressed pixels: 3 sigmas of the whole pyramid's blur.
_SPREAD_PX = int(np.ceil(C.GEL_KERNEL_SIGMAS * np.sqrt(sum(s * s for s in C.GEL_PYRAMID_SIGMAS) + C.GEL_FINAL_SIGMA ** 2)))


def render_image(penetration: np.ndarray, calib: OpticsData | None = None) -> np.ndarray:
    """RGB uint8 (H, W, 3) tactile image (no markers) of a penetration map in metres.

    The map may be the output resolution (``calib.shape``, default 240 x 320) or an integer
    fraction of it (the gel grid, :data:`~.constants.GEL_GRID_DOWNSAMPLE`): the gel surface and
    its colour change are then computed at the map's resolution and the change is upsampled
    bilinearly onto the full-resolution background (the gel is smooth at that scale).
    Zero penetration everywhere returns exactly (a copy of) the calibration background.
    """
    pen = np.asarray(penetration)
    calib = calib or load_optics()
    H, W = calib.shape
    f = W // pen.shape[1] if pen.ndim == 2 and pen.shape[1] else 0
    if pen.ndim != 2 or f < 1 or pen.shape[0] * f != H or pen.shape[1] * f != W:
        raise ValueError(f"penetration map must have shape {calib.shape} (H, W) or an integer fraction of it, "
                         f"got {pen.shape}")
    if not np.all(np.isfinite(pen)):
        raise ValueError("penetration map contains NaN or inf")
    img = calib.background.copy()
    pressed = pen > 0.0
    if not pressed.any():
        return img
    local = calib if f == 1 else load_optics(W // f, H // f)
    pixel = C.PIXEL_SIZE * W / C.IMAGE_WIDTH * f
    # Only the contact's neighbourhood can change colour: work on that crop.
    r0, r1, c0, c1 = _crop_box(pressed, -(-_SPREAD_PX // f))
    h = gel_surface(pen[r0:r1, c0:c1] / pixel, pyramid=tuple(s / f for s in C.GEL_PYRAMID_SIGMAS),
                    final_sigma=C.GEL_FINAL_SIGMA / f)
    gx, gy = surface_gradients(h)
    # Slopes within the first magnitude bin read as flat gel: no colour change, background kept.
    mag_bw = bin_width()[0]
    active = gx * gx + gy * gy >= np.float32(np.tan(mag_bw) ** 2)
    rr, cc = np.nonzero(active)
    if len(rr) == 0:
        return img
    i, j = normal_bins(gx[rr, cc], gy[rr, cc])
    coeff = np.take(local.delta_table, i * C.NUM_BINS + j, axis=0)  # (n, RGB, 6)
    feats = np.take(local.features, (rr + r0) * local.shape[1] + (cc + c0), axis=0)  # (n, 6)
    change = np.zeros((r1 - r0, c1 - c0, 3), np.float32)
    change[rr, cc] = np.einsum("nck,nk->nc", coeff, feats)
    if f > 1:
        change = cv2.resize(change, ((c1 - c0) * f, (r1 - r0) * f), interpolation=cv2.INTER_LINEAR)
    region = img[r0 * f:r1 * f, c0 * f:c1 * f]
    region[:] = np.clip(np.rint(region + change), 0, 255).astype(np.uint8)
    return img
