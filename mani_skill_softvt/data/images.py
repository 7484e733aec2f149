"""Images: resizing shared by the LeRobot export and the baselines' inputs; PNG writing."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..fileio import atomic_write


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


def write_png(path, image: np.ndarray) -> None:
    """Write an RGB uint8 image as PNG, atomically."""
    def write(tmp: Path):
        if not cv2.imwrite(str(tmp), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
            raise OSError(f"could not write {path}")

    atomic_write(Path(path), write)
