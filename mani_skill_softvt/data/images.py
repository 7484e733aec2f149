"""Image resizing shared by the LeRobot export and the baselines' inputs."""

from __future__ import annotations

import cv2
import numpy as np


def resize_image(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``image`` (H, W[, C]) resized to ``size`` = (height, width) by area averaging (dtype kept;
    integer images other than uint8 are resized in float and rounded back)."""
    h, w = size
    if image.shape[:2] == (h, w):
        return np.ascontiguousarray(image)
    if image.dtype == np.uint8:
        return cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
    out = cv2.resize(image.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)
    return np.rint(out).astype(image.dtype) if image.dtype.kind in "iu" else out.astype(image.dtype)
