"""Filesystem locations used across the package (committed data, user caches).

The committed data (``asset-data/``, the ``calibration-data/`` cards, ``demo-data/``) lives at the
repo's top level, in folders whose names no Python package can have; a wheel carries a copy of the
assets and cards inside the package, ``mani_skill_softvt/_data/{assets,calibration}``
(pyproject.toml maps it there). Each data location is, in this order: its environment variable; the
checkout's top-level folder when the package runs from a checkout (editable install, PYTHONPATH);
the copy installed with the package. No demos ship with the package: installed, ``DEMOS_DIR`` names a
directory inside it that writers refuse (:func:`writable_default`).
"""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_DIR = PACKAGE_DIR.parent  # the checkout when is_checkout(REPO_DIR); site-packages when installed
INSTALLED_DATA_DIR = PACKAGE_DIR / "_data"  # where the wheel puts assets/ and calibration/
PROJECT_NAME = "mani-skill-softvt"
# Each kind of committed data -> its folder in a checkout (the wheel's _data/ keeps the kind's name).
CHECKOUT_DATA_FOLDERS = {"assets": "asset-data", "calibration": "calibration-data", "demos": "demo-data"}


def is_checkout(repo_dir: Path) -> bool:
    """Whether ``repo_dir`` (the package's parent) is this project's source tree: it holds this
    project's pyproject.toml. An installed package's parent is site-packages, which has none."""
    try:
        text = (Path(repo_dir) / "pyproject.toml").read_text()
    except OSError:
        return False
    return f'name = "{PROJECT_NAME}"' in text


def data_dir(env_var: str, name: str, environ=None, repo_dir: Path = REPO_DIR,
             installed_dir: Path = INSTALLED_DATA_DIR) -> Path:
    """Directory of the committed data ``name`` (``assets``, ``calibration``, ``demos``): the
    environment variable ``env_var`` if set (and not empty), else the checkout's top-level folder
    for it (:data:`CHECKOUT_DATA_FOLDERS`), else the copy installed with the package."""
    value = (os.environ if environ is None else environ).get(env_var)
    if value:
        return Path(value)
    if is_checkout(repo_dir):
        return Path(repo_dir) / CHECKOUT_DATA_FOLDERS[name]
    return Path(installed_dir) / name


def running_from_checkout() -> bool:
    """Whether this package runs from the repo (editable install, PYTHONPATH), not from a wheel."""
    return is_checkout(REPO_DIR)


def inside_installed_package(path: Path, package_dir: Path | None = None) -> bool:
    """Whether ``path`` lies in the installed package (never true when running from a checkout,
    whose package directory holds only code)."""
    package_dir = Path(PACKAGE_DIR if package_dir is None else package_dir)
    if is_checkout(package_dir.parent):
        return False
    return Path(path).resolve().is_relative_to(package_dir.resolve())


def writable_default(path: Path, flag: str, env_var: str, package_dir: Path | None = None) -> Path:
    """``path``, a writing command's default output directory, unless it lies in the installed
    package: files written into site-packages are lost on the next reinstall and may not be
    writable at all, so there the command needs an explicit ``flag`` (ValueError naming it)."""
    package_dir = Path(PACKAGE_DIR if package_dir is None else package_dir)
    if inside_installed_package(path, package_dir):
        raise ValueError(f"the default output directory {path} is inside the installed package "
                         f"({package_dir}): pass {flag} DIR, or set {env_var} to a directory of your own "
                         f"(e.g. a checkout's top-level {CHECKOUT_DATA_FOLDERS.get(Path(path).name, Path(path).name)}/)")
    return Path(path)


def missing_data_hint(directory: Path, env_var: str, name: str, regenerate: str) -> str:
    """What to do when committed data is missing from ``directory``: where it looked, the variable
    that moves it, and where a complete copy comes from (no advice to regenerate it into an
    installed package)."""
    how = (f"regenerate it in this checkout with `{regenerate}`" if running_from_checkout()
           else "reinstall the package (its wheel carries the committed data)")
    return (f"searched {directory}; set {env_var} to a directory that holds it (a checkout's top-level "
            f"{CHECKOUT_DATA_FOLDERS.get(name, name)}/ has everything committed), or {how}")


ASSETS_DIR = data_dir("SOFTVT_ASSETS_DIR", "assets")
CALIBRATION_DIR = data_dir("SOFTVT_CALIBRATION_DIR", "calibration")
DEMOS_DIR = data_dir("SOFTVT_DEMOS_DIR", "demos")
CACHE_DIR = Path(os.environ.get("SOFTVT_CACHE_DIR", Path.home() / ".cache" / "mani_skill_softvt"))
# Warp compiles kernels on first use (~40 s on CPU); keep them across runs and processes.
WARP_CACHE_DIR = Path(os.environ.get("WARP_CACHE_PATH", CACHE_DIR / "warp"))
