"""Filesystem locations used across the package (repo-relative data, user caches)."""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_DIR = PACKAGE_DIR.parent
ASSETS_DIR = Path(os.environ.get("SOFTVT_ASSETS_DIR", REPO_DIR / "assets"))
CALIBRATION_DIR = Path(os.environ.get("SOFTVT_CALIBRATION_DIR", REPO_DIR / "calibration"))
DEMOS_DIR = Path(os.environ.get("SOFTVT_DEMOS_DIR", REPO_DIR / "demos"))
CACHE_DIR = Path(os.environ.get("SOFTVT_CACHE_DIR", Path.home() / ".cache" / "mani_skill_softvt"))
# Warp compiles kernels on first use (~40 s on CPU); keep them across runs and processes.
WARP_CACHE_DIR = Path(os.environ.get("WARP_CACHE_PATH", CACHE_DIR / "warp"))
