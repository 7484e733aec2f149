"""Taxim-style optics: gel smoothing, surface normals, polynomial colour lookup, background.

The photometric calibration (polynomial lookup table and background frame of a real GelSight
Mini) is read from the installed ``taxim`` package (MIT licence), never copied into this repo.
The image is the background plus the colour *change* the normals cause, so a frame without
contact is exactly the background.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

import cv2
import numpy as np

from . import constants as C


@dataclass(frozen=True)
class Calibration:
    poly: np.ndarray  # (bins, bins, 6, 3): per (gradient magnitude, direction) bin, RGB polynomial coefficients
    background: np.ndarray  # (H, W, 3) uint8 RGB at the output resolution
    features: np.ndarray  # (H*W, 6): [x^2, y^2, xy, x, y, 1] in calibration pixel coordinates
    flat: np.ndarray  # (H*W, 3): the polynomial's response to a flat gel (subtracted)
    pixmm_calib: float


@lru_cache(maxsize=None)
def load_calibration(width: int = C.IMAGE_WIDTH, height: int = C.IMAGE_HEIGHT) -> Calibration:
    """GelSight Mini calibration from the installed ``taxim`` package, at the output resolution."""
    try:
        root = resources.files("taxim") / "calib" / "gelsight_mini"
    except ModuleNotFoundError as e:
        raise ImportError("the tactile sensor needs the 'taxim' package (pip install taxim==1.4.1)") from e
    with resources.as_file(root) as folder:
        poly = np.load(folder / "polycalib.npz")
        # taxim stores the channels as (b, g, r) under the names grad_r/g/b swapped: stack as RGB.
        table = np.stack([poly["grad_b"], poly["grad_g"], poly["grad_r"]], axis=-1).astype(np.float64)
        f0_bgr = np.load(folder / "dataPack.npz", allow_pickle=True)["f0"]
        params = json.loads((folder / "params.json").read_text())["sensor"]
    if table.shape[:2] != (C.NUM_BINS, C.NUM_BINS):
        raise ValueError(f"unexpected taxim lookup table shape {table.shape}")
    background = cv2.resize(cv2.cvtColor(f0_bgr, cv2.COLOR_BGR2RGB), (width, height), interpolation=cv2.INTER_AREA)
    sx, sy = params["w"] / width, params["h"] / height
    yy, xx = np.meshgrid(np.arange(height) * sy, np.arange(width) * sx, indexing="ij")
    x, y = xx.ravel(), yy.ravel()
    features = np.stack([x * x, y * y, x * y, x, y, np.ones_like(x)], axis=1)
    flat_idx = _bin_indices(np.zeros(1), np.zeros(1))
    flat = features @ table[flat_idx[0][0], flat_idx[1][0]]
    return Calibration(table, background, features, flat, float(params["pixmm"]))


def _bin_indices(grad_mag: np.ndarray, grad_dir: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mag_bin = 0.5 * np.pi / (C.NUM_BINS - 1)
    dir_bin = 2.0 * np.pi / (C.NUM_BINS - 1)
    i = np.clip(np.floor(grad_mag / mag_bin).astype(np.int64), 0, C.NUM_BINS - 1)
    j = np.clip(np.floor((grad_dir + np.pi) / dir_bin).astype(np.int64), 0, C.NUM_BINS - 1)
    return i, j


def gel_deformation(penetration: np.ndarray, pyramid=C.GEL_PYRAMID_SIGMAS, final_sigma: float = C.GEL_FINAL_SIGMA) -> np.ndarray:
    """Gel surface displacement (same units as ``penetration``): conforms to the object inside
    the contact and relaxes smoothly around it (coarse-to-fine Gaussian pyramid)."""
    d = np.asarray(penetration, np.float64)
    if not d.any():
        return np.zeros_like(d)
    h = d.copy()
    for s in pyramid:
        h = np.maximum(d, cv2.GaussianBlur(h, (0, 0), s, borderType=cv2.BORDER_REPLICATE))
    return cv2.GaussianBlur(h, (0, 0), final_sigma, borderType=cv2.BORDER_REPLICATE)


def surface_normals(height_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient magnitude as a slope angle in [0, pi/2) and gradient direction in [-pi, pi]."""
    gy, gx = np.gradient(height_px)
    return np.arctan(np.hypot(gx, gy)), np.arctan2(gy, gx)


def render_image(penetration: np.ndarray, calib: Calibration | None = None, pixel: float = C.PIXEL_SIZE) -> np.ndarray:
    """RGB uint8 tactile image of a penetration map (m). Zero penetration gives the background."""
    calib = calib or load_calibration(penetration.shape[1], penetration.shape[0])
    bg = calib.background
    rows, cols = np.nonzero(penetration > 0)
    if len(rows) == 0:
        return bg.copy()
    # Work on the contact's neighbourhood only: the gel relaxes within ~3 coarse sigmas.
    H, W = penetration.shape
    m = int(np.ceil(3 * max(C.GEL_PYRAMID_SIGMAS)))
    r0, r1 = max(0, rows.min() - m), min(H, rows.max() + m + 1)
    c0, c1 = max(0, cols.min() - m), min(W, cols.max() + m + 1)
    h = gel_deformation(penetration[r0:r1, c0:c1])
    mag, ang = surface_normals(h / pixel)
    i, j = _bin_indices(mag, ang)
    active = i > 0  # slopes below the first magnitude bin read as flat gel (no colour change)
    if not active.any():
        return bg.copy()
    rr, cc = np.nonzero(active)
    flat_index = (rr + r0) * W + (cc + c0)
    response = np.einsum("nk,nkc->nc", calib.features[flat_index], calib.poly[i[active], j[active]])
    img = bg.copy()
    # The table is in 0-255 intensity units; add the colour change over the flat-gel response.
    val = bg[rr + r0, cc + c0].astype(np.float64) + response - calib.flat[flat_index]
    img[rr + r0, cc + c0] = np.clip(np.rint(val), 0, 255).astype(np.uint8)
    return img
