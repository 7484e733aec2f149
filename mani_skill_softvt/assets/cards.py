"""Asset cards: one JSON file per object and per prop, validated on load.

Objects live in ``asset-data/objects/<asset_id>/card.json``; rigid twins have their own card that
points at the soft asset's files (surface, tets, visuals) and lists their own convex collision
parts; a twin has no elastic constants (it is a PhysX rigid body). Props live in ``asset-data/props/<name>/card.json``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import trimesh

from .. import paths
from ..paths import ASSETS_DIR, missing_data_hint
from .materials import SoftMaterial

ASSET_IDS = [
    "soft_pastry001", "soft_pastry002", "soft_pastry003", "soft_stw_cube_hq", "soft_pastry005",
    "soft_stw_cylinder_hq", "soft_pastry011", "soft_stw_cuboid_hq", "soft_stw_sphere_hq", "soft_pastry010",
]


def twin_id(soft_asset_id: str) -> str:
    """Id of the rigid twin of a soft asset: soft_<name> -> rigid_<name>."""
    if not soft_asset_id.startswith("soft_"):
        raise ValueError(f"'{soft_asset_id}' is not a soft asset id (soft_...)")
    return "rigid_" + soft_asset_id[len("soft_"):]


TWIN_IDS = [twin_id(a) for a in ASSET_IDS]
PROP_NAMES = ["table", "basket", "plate", "tea_tin", "mug", "apple"]

_BUILD = "python -m mani_skill_softvt.assets.build"


def _remedy() -> str:
    """How to repair a damaged asset file: rebuild it in a checkout; an installed package's
    copy comes from its wheel (the builder would not write into site-packages by default)."""
    if paths.running_from_checkout():
        return f"rebuild the assets with: {_BUILD}"
    return "reinstall the package (its wheel carries the assets), or set SOFTVT_ASSETS_DIR to a checkout's asset-data/"


def _not_found_hint(assets_dir: Path) -> str:
    return missing_data_hint(assets_dir, "SOFTVT_ASSETS_DIR", "assets", _BUILD)


_OBJECT_FIELDS = {
    "asset_id": str, "twin_id": str, "kind": str, "description": str, "dimensions": list, "volume": float,
    "mass": float, "density": float, "friction": float, "color": list, "resolution": int, "files": dict,
    "counts": dict,
}
_SOFT_FIELDS = {"youngs_modulus": float, "poisson_ratio": float, "damping": float}


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a plain OBJ file (as written by :func:`write_obj`)."""
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                f.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    if not v or not f:
        raise ValueError(f"{path}: no vertices or faces; {_remedy()}")
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int32)


def _load_json(path: Path, what: str, assets_dir: Path) -> dict:
    if not path.is_file():
        raise FileNotFoundError(f"{what} card not found: {path}; {_not_found_hint(assets_dir)}")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{what} card {path} is not valid JSON ({e}); {_remedy()}") from e


def _check_fields(data: dict, fields: dict, path: Path) -> None:
    for key, typ in fields.items():
        if key not in data:
            raise ValueError(f"card {path} is missing field '{key}'; {_remedy()}")
        ok = isinstance(data[key], (int, float)) if typ is float else isinstance(data[key], typ)
        if not ok or isinstance(data[key], bool):
            raise ValueError(f"card {path}: field '{key}' should be {typ.__name__}, got {data[key]!r}")


def _file(card_dir: Path, rel: str, card_path: Path) -> Path:
    p = (card_dir / rel).resolve()
    if not p.is_file():
        raise FileNotFoundError(f"card {card_path} refers to a missing file {p}; {_remedy()}")
    return p


@dataclass(frozen=True)
class AssetCard:
    asset_id: str
    twin_id: str
    kind: str  # "soft" or "rigid"
    description: str  # the words instructions use for it
    dimensions: tuple  # AABB extents (m)
    volume: float  # m^3
    mass: float  # kg = density * volume
    density: float
    youngs_modulus: float | None  # None for a rigid twin (as are poisson_ratio and damping)
    poisson_ratio: float | None
    damping: float | None
    friction: float
    color: tuple  # RGBA of the body
    resolution: int
    surface_file: Path
    tet_file: Path
    visual_parts: tuple  # ((name, path, rgba), ...): body first, then decorations
    counts: dict
    collision_files: tuple = ()  # rigid twins: convex parts (OBJ), object frame
    rest_pose: tuple | None = None  # rigid twins: [p, q_wxyz] of the object frame resting on a table

    @property
    def rigid(self) -> bool:
        return self.kind == "rigid"

    def convex_parts(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Convex collision parts of a rigid twin: [(vertices, faces), ...] in the object frame."""
        return [read_obj(p) for p in self.collision_files]

    def surface_mesh(self):
        v, f = read_obj(self.surface_file)
        return trimesh.Trimesh(v, f, process=False)

    def tet_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        with np.load(self.tet_file) as d:
            return d["vertices"].astype(np.float64), d["tets"].astype(np.int32)

    def material(self) -> SoftMaterial:
        """The FEM material of a soft asset (a rigid twin has none)."""
        if self.rigid:
            raise ValueError(f"'{self.asset_id}' is a rigid twin (a PhysX rigid body): it has no FEM material")
        return SoftMaterial(self.youngs_modulus, self.poisson_ratio, self.density, self.damping, self.friction)


@lru_cache(maxsize=None)
def load_card(asset_id: str, assets_dir: Path = ASSETS_DIR) -> AssetCard:
    """Load and validate an object card (soft id or rigid twin id)."""
    if asset_id not in ASSET_IDS and asset_id not in TWIN_IDS:
        raise ValueError(f"unknown asset '{asset_id}'; known: {ASSET_IDS + TWIN_IDS}")
    path = Path(assets_dir) / "objects" / asset_id / "card.json"
    d = _load_json(path, f"asset '{asset_id}'", assets_dir)
    _check_fields(d, _OBJECT_FIELDS, path)
    if d["asset_id"] != asset_id:
        raise ValueError(f"card {path} describes '{d['asset_id']}', expected '{asset_id}'")
    if d["kind"] not in ("soft", "rigid"):
        raise ValueError(f"card {path}: kind must be 'soft' or 'rigid', got {d['kind']!r}")
    rigid = d["kind"] == "rigid"
    if not rigid:
        _check_fields(d, _SOFT_FIELDS, path)
        if not (d["youngs_modulus"] > 0 and 0 <= d["poisson_ratio"] < 0.5):
            raise ValueError(f"card {path}: material values out of range (E > 0, 0 <= nu < 0.5)")
    if not (d["density"] > 0 and d["mass"] > 0 and d["friction"] >= 0):
        raise ValueError(f"card {path}: density and mass must be > 0 and friction >= 0")
    files = d["files"]
    if rigid and not (isinstance(d.get("rest_pose"), list) and len(d["rest_pose"]) == 7):
        raise ValueError(f"card {path}: a rigid twin needs rest_pose [x, y, z, qw, qx, qy, qz]; {_remedy()}")
    for key in ("surface", "tets", "visual") + (("collision",) if rigid else ()):
        if key not in files:
            raise ValueError(f"card {path}: files.{key} missing; {_remedy()}")
    parts = tuple((p["name"], _file(path.parent, p["file"], path), tuple(p["color"])) for p in files["visual"])
    return AssetCard(
        asset_id=asset_id, twin_id=d["twin_id"], kind=d["kind"], description=d["description"],
        dimensions=tuple(d["dimensions"]), volume=float(d["volume"]), mass=float(d["mass"]),
        density=float(d["density"]), youngs_modulus=None if rigid else float(d["youngs_modulus"]),
        poisson_ratio=None if rigid else float(d["poisson_ratio"]), damping=None if rigid else float(d["damping"]),
        friction=float(d["friction"]),
        color=tuple(d["color"]), resolution=int(d["resolution"]),
        surface_file=_file(path.parent, files["surface"], path), tet_file=_file(path.parent, files["tets"], path),
        visual_parts=parts, counts=dict(d["counts"]),
        collision_files=tuple(_file(path.parent, f, path) for f in files.get("collision", ())) if rigid else (),
        rest_pose=tuple(float(x) for x in d["rest_pose"]) if rigid else None,
    )


@dataclass(frozen=True)
class PropCard:
    name: str
    dimensions: tuple
    friction: float
    visual_file: Path
    color: tuple
    collision_files: tuple  # convex parts (OBJ), prop frame
    regions: dict  # name -> (lo xyz, hi xyz) axis-aligned boxes in the prop frame (e.g. "interior")

    def convex_parts(self) -> list[tuple[np.ndarray, np.ndarray]]:
        return [read_obj(p) for p in self.collision_files]


@lru_cache(maxsize=None)
def load_prop(name: str, assets_dir: Path = ASSETS_DIR) -> PropCard:
    if name not in PROP_NAMES:
        raise ValueError(f"unknown prop '{name}'; known: {PROP_NAMES}")
    path = Path(assets_dir) / "props" / name / "card.json"
    d = _load_json(path, f"prop '{name}'", assets_dir)
    _check_fields(d, {"name": str, "dimensions": list, "friction": float, "color": list, "files": dict,
                      "regions": dict}, path)
    return PropCard(
        name=name, dimensions=tuple(d["dimensions"]), friction=float(d["friction"]),
        visual_file=_file(path.parent, d["files"]["visual"], path), color=tuple(d["color"]),
        collision_files=tuple(_file(path.parent, f, path) for f in d["files"]["collision"]),
        regions={k: (tuple(v[0]), tuple(v[1])) for k, v in d["regions"].items()},
    )
