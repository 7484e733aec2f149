"""Generate every asset file under ``asset-data/`` (bit-identical on every run).

    python -m mani_skill_softvt.assets.build            # all objects, twins and props
    python -m mani_skill_softvt.assets.build --out /tmp/assets --only soft_stw_cube_hq

Objects: surface mesh (OBJ), tetrahedral mesh at the default hex resolution (NPZ), visual parts
(OBJ, one colour each) and a card (JSON). Rigid twins (PhysX rigid bodies) get a card that reuses
the soft files and their own convex collision parts (coacd decomposition of the soft surface).
Props: visual mesh, convex collision parts (coacd for the concave basket and plate) and a card.
Every file is written to a temporary name and renamed, so an interrupted build never leaves a
half-written file; a rerun rewrites identical bytes.
"""

from __future__ import annotations

import argparse
import io
import json
from pathlib import Path

import coacd
import numpy as np
import trimesh
from scipy.spatial.transform import Rotation
from tqdm import tqdm
from trimesh.poses import compute_stable_poses

from ..fileio import atomic_write
from ..paths import ASSETS_DIR, writable_default
from .cards import ASSET_IDS, PROP_NAMES, read_obj, twin_id
from .materials import MATERIALS, PROP_FRICTION, TWIN_MAX_CONVEX_PARTS
from .shapes import object_parts
from .tetmesh import tet_quality, tetrahedralize

DEFAULT_RESOLUTION = 6  # the paper's hex resolution
REST_POSE_MAX_TILT = np.deg2rad(25.0)  # a twin's rest pose stays this close to the modelled orientation
# Stable faces whose probability and tilt agree within these are ties (mirror images on a symmetric
# body): float noise (qhull's face order, 1e-9 m vertex noise) moves them by < 2e-8 and < 2e-6 rad,
# while distinct faces differ by more (pastry001's two best by 1e-6 in probability). Within a tie the
# normal decides, its components compared within NORMAL_TIE (noise moves them by < 1e-6; distinct
# faces of the twins differ by > 1e-3).
PROBABILITY_TIE = 1e-7
TILT_TIE = 1e-5  # rad
NORMAL_TIE = 1e-5
DESCRIPTIONS = {
    "soft_pastry001": "white swirled pastry", "soft_pastry002": "panda-face pastry",
    "soft_pastry003": "small chocolate rectangular pastry", "soft_stw_cube_hq": "soft cream-colored cube",
    "soft_pastry005": "yellow square layered pastry", "soft_stw_cylinder_hq": "soft tan cylinder",
    "soft_pastry011": "golden pastry", "soft_stw_cuboid_hq": "golden knotted pastry",
    "soft_stw_sphere_hq": "soft red ball", "soft_pastry010": "orange pumpkin-shaped pastry",
}


def _atomic_bytes(path: Path, data: bytes) -> None:
    atomic_write(path, lambda tmp: tmp.write_bytes(data))


def obj_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """Plain OBJ, micrometre precision, fixed formatting (deterministic)."""
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in np.asarray(vertices, dtype=np.float64)]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(faces)]
    return ("\n".join(lines) + "\n").encode()


def write_obj(path: Path, vertices, faces) -> None:
    _atomic_bytes(path, obj_bytes(vertices, faces))


def _npz_bytes(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # zip entries carry a fixed 1980 timestamp: deterministic bytes
    return buf.getvalue()


def _json_bytes(d: dict) -> bytes:
    return (json.dumps(d, indent=2, sort_keys=True) + "\n").encode()


def _r(x, nd=9):
    # + 0.0 turns a rounded -0.0 into 0.0: the sign of a value below the rounding is noise.
    return [round(float(v), nd) + 0.0 for v in x] if np.ndim(x) else round(float(x), nd) + 0.0


def build_object(asset_id: str, out: Path, resolution: int = DEFAULT_RESOLUTION) -> dict:
    d = out / "objects" / asset_id
    body, decorations = object_parts(asset_id)
    write_obj(d / "surface.obj", body.vertices, body.faces)
    # Re-read what was written, so the tets conform to the file's (rounded) surface exactly.
    sv, sf = read_obj(d / "surface.obj")
    surface = trimesh.Trimesh(sv, sf, process=False)
    tv, tt = tetrahedralize(surface, resolution)
    _atomic_bytes(d / "tets.npz", _npz_bytes(vertices=tv, tets=tt.astype(np.int32)))
    visual = [{"name": "body", "file": "surface.obj", "color": list(body.color)}]
    for part in decorations:
        write_obj(d / f"deco_{part.name}.obj", part.vertices, part.faces)
        visual.append({"name": part.name, "file": f"deco_{part.name}.obj", "color": list(part.color)})
    density, e, nu, damping, mu = MATERIALS[asset_id]
    q = tet_quality(tv, tt)
    volume = float(surface.volume)
    card = {
        "asset_id": asset_id, "twin_id": twin_id(asset_id), "kind": "soft",
        "description": DESCRIPTIONS[asset_id], "dimensions": _r(surface.extents), "volume": _r(volume, 12),
        "mass": _r(density * volume, 9), "density": density, "youngs_modulus": e, "poisson_ratio": nu,
        "damping": damping, "friction": mu, "color": list(body.color), "resolution": resolution,
        "files": {"surface": "surface.obj", "tets": "tets.npz", "visual": visual},
        "counts": {"surface_vertices": len(sv), "surface_faces": len(sf), "tet_nodes": q["n_nodes"],
                   "tets": q["n_tets"]},
        "tet_quality": {"min_volume": _r(q["min_volume"], 15), "min_shape": _r(q["min_shape"], 6),
                        "mean_shape": _r(q["mean_shape"], 6),
                        "volume_error": _r(q["total_volume"] / volume - 1.0, 9)},
    }
    _atomic_bytes(d / "card.json", _json_bytes(card))
    build_twin(card, out)
    return card


def build_twin(soft_card: dict, out: Path) -> dict:
    """The rigid twin of a soft asset: same surface, tets (its evaluation nodes), visuals, density,
    mass, friction and colour; no elastic constants (PhysX simulates it as a rigid body); convex
    collision parts from coacd (one hull for the convex primitives, a few for the pastries)."""
    asset_id = soft_card["asset_id"]
    rigid_id = soft_card["twin_id"]
    d = out / "objects" / rigid_id
    v, f = read_obj(out / "objects" / asset_id / "surface.obj")
    coll = []
    for i, (pv, pf) in enumerate(_convex_decomposition(v, f, TWIN_MAX_CONVEX_PARTS)):
        write_obj(d / f"collision_{i:02d}.obj", pv, pf)
        coll.append(f"collision_{i:02d}.obj")
    twin = {k: val for k, val in soft_card.items() if k not in ("youngs_modulus", "poisson_ratio", "damping")}
    twin.update(asset_id=rigid_id, twin_id=asset_id, kind="rigid",
                rest_pose=_r(stable_rest_pose([read_obj(d / c) for c in coll])))
    twin["files"] = {"surface": f"../{asset_id}/surface.obj", "tets": f"../{asset_id}/tets.npz",
                     "visual": [{**p, "file": f"../{asset_id}/{p['file']}"} for p in soft_card["files"]["visual"]],
                     "collision": coll}
    _atomic_bytes(d / "card.json", _json_bytes(twin))
    return twin


def stable_rest_pose(parts) -> np.ndarray:
    """Pose [p, q_wxyz] that sets a rigid body (convex ``parts`` [(vertices, faces), ...], uniform
    density) resting on a table: the most stable pose near the modelled orientation, bottom at
    z = 0. A soft asset sags onto its supports; its rigid twin, modelled in the same orientation,
    may stand on a vertex or an edge (the faceted ball, the lying cylinder) and roll away.
    trimesh's stable poses (sigma 0: deterministic) are the hull faces the centre of mass
    projects into. Only their face normals are used: the body is tilted onto the chosen face by
    the shortest arc, so the twin keeps its soft asset's heading (trimesh's frames add a yaw built
    from the tiny horizontal part of a nearly vertical normal: arbitrary, up to 22 deg on these
    assets, and different from machine to machine). The face is chosen by :func:`pick_rest_face`."""
    meshes = [trimesh.Trimesh(v, f) for v, f in parts]
    com = sum(m.center_mass * m.volume for m in meshes) / sum(m.volume for m in meshes)
    hull = trimesh.util.concatenate(meshes).convex_hull
    transforms, probability = compute_stable_poses(hull, center_mass=com, sigma=0.0, n_samples=1)
    normals = -transforms[:, 2, :3]  # outward normal (object frame) of the face each pose rests on
    tilt = np.arccos(np.clip(-normals[:, 2], -1.0, 1.0))
    i = pick_rest_face(normals, tilt, probability)
    rotation, _ = Rotation.align_vectors([[0.0, 0.0, -1.0]], [normals[i]])  # one pair: the shortest arc
    rotated = rotation.apply(hull.vertices)
    # Keep the object where it was in xy (its footprint's centre), bottom on the table.
    lo, hi = hull.vertices.min(axis=0), hull.vertices.max(axis=0)
    rlo, rhi = rotated.min(axis=0), rotated.max(axis=0)
    p = np.array([*(0.5 * (lo + hi) - 0.5 * (rlo + rhi))[:2], -rlo[2]])
    return np.concatenate([p, rotation.as_quat(scalar_first=True)])


def _within(candidates: np.ndarray, values: np.ndarray, tol: float) -> np.ndarray:
    """The candidates whose value is within ``tol`` of the smallest: a tie group measured from the
    best, so float noise cannot split an exact tie (rounding onto a fixed grid can, when the tied
    value sits on a grid line)."""
    v = values[candidates]
    return candidates[v <= v.min() + tol]


def pick_rest_face(normals: np.ndarray, tilt: np.ndarray, probability: np.ndarray) -> int:
    """Index of the stable face a twin rests on, from trimesh's candidates (outward ``normals``,
    ``tilt`` from the modelled orientation in rad, ``probability``). The nearest pose can be
    marginal (a pastry tipped in PhysX from its 6 deg pose): among the faces within
    REST_POSE_MAX_TILT take the widest basin (trimesh's probability), then the least tilt.
    Symmetric bodies have several mirror-image faces tied on both; trimesh lists them in qhull's
    face order, which differs from machine to machine, so a tie is broken by the normal: smallest
    n_y, then largest n_x (of the ten twins, the order that keeps the most committed cards)."""
    group = np.flatnonzero(tilt <= max(REST_POSE_MAX_TILT, tilt.min()))
    group = _within(group, -probability, PROBABILITY_TIE)
    group = _within(group, tilt, TILT_TIE)
    group = _within(group, normals[:, 1], NORMAL_TIE)
    group = _within(group, -normals[:, 0], NORMAL_TIE)
    # Left: normals within NORMAL_TIE of each other (poses 1e-5 rad apart; no committed twin has
    # two); the exact values decide.
    return int(min(group, key=lambda i: (normals[i, 1], -normals[i, 0], normals[i, 2])))


# ------------------------------------------------------------------------------------ props
def _box(lo, hi):
    m = trimesh.creation.box(bounds=np.array([lo, hi], dtype=np.float64))
    return np.asarray(m.vertices), np.asarray(m.faces)


def _basket_shell(bottom=(0.14, 0.11), top=(0.17, 0.14), height=0.06, wall=0.006):
    """Open-top tapered box with thick walls, one closed (watertight) surface."""
    bx, by = bottom[0] / 2, bottom[1] / 2
    tx, ty = top[0] / 2, top[1] / 2
    ob = [(-bx, -by, 0), (bx, -by, 0), (bx, by, 0), (-bx, by, 0)]
    ot = [(-tx, -ty, height), (tx, -ty, height), (tx, ty, height), (-tx, ty, height)]
    it = [(-tx + wall, -ty + wall, height), (tx - wall, -ty + wall, height), (tx - wall, ty - wall, height),
          (-tx + wall, ty - wall, height)]
    ib = [(-bx + wall, -by + wall, wall), (bx - wall, -by + wall, wall), (bx - wall, by - wall, wall),
          (-bx + wall, by - wall, wall)]
    v = np.array(ob + ot + it + ib, dtype=np.float64)
    f = [(0, 2, 1), (0, 3, 2)]  # outer bottom (down)
    for i in range(4):
        j = (i + 1) % 4
        f += [(i, j, 4 + j), (i, 4 + j, 4 + i)]  # outer side
        f += [(4 + i, 4 + j, 8 + j), (4 + i, 8 + j, 8 + i)]  # rim
        f += [(8 + i, 8 + j, 12 + j), (8 + i, 12 + j, 12 + i)]  # inner side (faces inward)
    f += [(12, 13, 14), (12, 14, 15)]  # inner floor (up)
    return v, np.asarray(f, dtype=np.int32)


def _plate_solid(radius=0.09, floor=0.006, rim_height=0.018, flat=0.065, sections=32):
    profile = np.array([[0.0, 0.0], [flat + 0.01, 0.0], [radius, rim_height - 0.006], [radius, rim_height],
                        [radius - 0.006, rim_height], [flat, floor], [0.0, floor]])
    m = trimesh.creation.revolve(profile, sections=sections)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _convex_decomposition(v, f, max_parts: int = 16):
    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(v, f), threshold=0.05, seed=0, max_convex_hull=max_parts)
    return sorted(((np.asarray(pv), np.asarray(pf)) for pv, pf in parts), key=lambda p: tuple(p[0].mean(axis=0).round(6)))


def _cylinder(r, h, sections=24):
    m = trimesh.creation.cylinder(radius=r, height=h, sections=sections)
    v = np.asarray(m.vertices) + [0.0, 0.0, h / 2]
    return v, np.asarray(m.faces)


def _sphere(r):
    m = trimesh.creation.icosphere(subdivisions=2, radius=r)
    return np.asarray(m.vertices) + [0.0, 0.0, r], np.asarray(m.faces)


def build_prop(name: str, out: Path) -> dict:
    d = out / "props" / name
    regions = {}
    if name == "table":
        v, f = _box((-0.6, -0.8, -0.05), (0.6, 0.8, 0.0))
        parts, color = [(v, f)], (0.55, 0.42, 0.30, 1.0)
        regions["top"] = ((-0.6, -0.8, 0.0), (0.6, 0.8, 0.0))
    elif name == "basket":
        v, f = _basket_shell()
        parts, color = _convex_decomposition(v, f), (0.62, 0.45, 0.25, 1.0)
        regions["interior"] = ((-0.064, -0.049, 0.006), (0.064, 0.049, 0.06))
    elif name == "plate":
        v, f = _plate_solid()
        parts, color = _convex_decomposition(v, f), (0.92, 0.92, 0.95, 1.0)
        regions["top"] = ((-0.065, -0.065, 0.006), (0.065, 0.065, 0.05))
    elif name == "tea_tin":
        v, f = _box((-0.03, -0.03, 0.0), (0.03, 0.03, 0.09))
        parts, color = [(v, f)], (0.15, 0.35, 0.65, 1.0)
    elif name == "mug":
        v, f = _cylinder(0.04, 0.09)
        parts, color = [(v, f)], (0.95, 0.95, 0.92, 1.0)
    elif name == "apple":
        v, f = _sphere(0.035)
        parts, color = [(v, f)], (0.55, 0.75, 0.2, 1.0)
    else:
        raise ValueError(f"unknown prop '{name}'")
    write_obj(d / "visual.obj", v, f)
    coll = []
    for i, (pv, pf) in enumerate(parts):
        write_obj(d / f"collision_{i:02d}.obj", pv, pf)
        coll.append(f"collision_{i:02d}.obj")
    lo, hi = v.min(axis=0), v.max(axis=0)
    card = {"name": name, "dimensions": _r(hi - lo), "friction": PROP_FRICTION.get(name, PROP_FRICTION["distractor"]),
            "color": list(color), "files": {"visual": "visual.obj", "collision": coll},
            "regions": {k: [_r(a), _r(b)] for k, (a, b) in regions.items()}}
    _atomic_bytes(d / "card.json", _json_bytes(card))
    return card


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.assets.build", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=None,
                    help=f"output directory (default {ASSETS_DIR}: $SOFTVT_ASSETS_DIR, else the checkout's asset-data/; "
                         "needed when the package is installed)")
    ap.add_argument("--only", nargs="*", help="asset ids or prop names to build (default: all)")
    ap.add_argument("--resolution", type=int, default=DEFAULT_RESOLUTION)
    args = ap.parse_args(argv)

    try:
        out = args.out if args.out is not None else writable_default(ASSETS_DIR, "--out", "SOFTVT_ASSETS_DIR")
    except ValueError as e:
        ap.error(str(e))
    names = args.only or (ASSET_IDS + PROP_NAMES)
    unknown = [n for n in names if n not in ASSET_IDS and n not in PROP_NAMES]
    if unknown:
        ap.error(f"unknown names {unknown}; objects: {ASSET_IDS}; props: {PROP_NAMES}")
    for name in tqdm(names, desc="building assets"):
        if name in ASSET_IDS:
            c = build_object(name, out, args.resolution)
            tqdm.write(f"{name:<22} {c['mass'] * 1e3:6.1f} g  {c['counts']['tet_nodes']:4d} nodes "
                       f"{c['counts']['tets']:5d} tets  dims {[round(x * 1e3) for x in c['dimensions']]} mm")
        else:
            c = build_prop(name, out)
            tqdm.write(f"{name:<22} {len(c['files']['collision'])} convex parts")


if __name__ == "__main__":
    main()
