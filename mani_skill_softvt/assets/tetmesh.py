"""Tetrahedral meshes for the FEM: structured box grids and tet-mesh surface extraction (pure numpy)."""

from __future__ import annotations

import itertools

import numpy as np
import trimesh

# Kuhn (Freudenthal) split of a hex into 6 tets sharing the main diagonal; neighbouring hexes
# agree on face diagonals, so the mesh is conforming.
_KUHN_PATHS = list(itertools.permutations(range(3)))
# Thin objects still get a few layers of elements through their thickness (bending, squeeze).
MIN_CELLS_PER_AXIS = 4


def tet_signed_volumes(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    v = np.asarray(vertices, dtype=np.float64)
    a, b, c, d = (v[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def box_tetmesh(size, resolution: int, min_cells: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Structured tet mesh of a box of full ``size`` (m), origin at the centre of its bottom face.

    ``resolution`` cells along the longest side, the others proportional (at least ``min_cells``).
    Every tet is positively oriented.
    """
    size = np.asarray(size, dtype=np.float64)
    if size.shape != (3,) or np.any(size <= 0) or resolution < 1:
        raise ValueError(f"box_tetmesh needs 3 positive extents and resolution >= 1, got {size}, {resolution}")
    n = np.maximum(max(1, min_cells), np.round(size / size.max() * resolution).astype(int))
    axes = [np.linspace(-size[0] / 2, size[0] / 2, n[0] + 1), np.linspace(-size[1] / 2, size[1] / 2, n[1] + 1),
            np.linspace(0.0, size[2], n[2] + 1)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    idx = np.arange(len(grid)).reshape(n[0] + 1, n[1] + 1, n[2] + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(n[0]), np.arange(n[1]), np.arange(n[2]), indexing="ij"))
    tets = []
    for path in _KUHN_PATHS:
        corner = np.zeros((3, len(i)), dtype=int)
        verts = [idx[i, j, k]]
        for axis in path:
            corner[axis] += 1
            verts.append(idx[i + corner[0], j + corner[1], k + corner[2]])
        tets.append(np.stack(verts, axis=1))
    tets = np.concatenate(tets).astype(np.int32)
    flip = tet_signed_volumes(grid, tets) < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return grid, tets


def surface_of_tets(tets: np.ndarray) -> np.ndarray:
    """Boundary triangles of a tet mesh (faces used by exactly one tet), outward-oriented.

    Assumes positively oriented tets (det[v1-v0, v2-v0, v3-v0] > 0), for which the faces below
    have outward normals.
    """
    tets = np.asarray(tets, dtype=np.int64)
    faces = np.concatenate([tets[:, [0, 2, 1]], tets[:, [0, 1, 3]], tets[:, [1, 2, 3]], tets[:, [0, 3, 2]]])
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inverse.ravel()] == 1].astype(np.int32)


def join_meshes(meshes) -> tuple[np.ndarray, np.ndarray]:
    """One mesh of several ``(vertices (N, 3), faces (M, k))``: faces renumbered into the joined
    vertices (dtypes kept: the FEM's float32 nodes stay float32)."""
    meshes = list(meshes)
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes[:-1]])
    return (np.concatenate([np.asarray(v) for v, _ in meshes]),
            np.concatenate([np.asarray(f) + int(o) for (_, f), o in zip(meshes, offsets)]))


def tetrahedralize(mesh, resolution: int = 6, volume_correct: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Volumetric tet mesh of a watertight, star-shaped surface at hex ``resolution``.

    The paper simulates its objects on a hexahedral grid of resolution 6 (cells along the
    longest side). Here a structured grid of the bounding box (split into positively oriented
    tets) is mapped onto the body: a grid point at box-normalised position p goes to
    ``c + |p|_inf * (s(p) - c)``, where s(p) is where the ray from the centre c through p meets
    the surface. Boundary nodes land exactly on the surface, the map is continuous and
    monotone along each ray, so no tet inverts for star-shaped bodies. The piecewise-linear
    boundary cuts a little volume off convex surfaces; ``volume_correct`` rescales about c so
    the tet volume equals the surface's (a uniform <2 % push outward), keeping mass = rho * V.
    """
    if not isinstance(mesh, trimesh.Trimesh) or not mesh.is_watertight:
        raise ValueError("tetrahedralize needs a watertight trimesh.Trimesh (repair or close the surface first)")
    lo, hi = mesh.bounds
    c = (lo + hi) / 2.0
    half = (hi - lo) / 2.0
    grid, tets = box_tetmesh(2.0 * half, resolution, min_cells=MIN_CELLS_PER_AXIS)
    p = (grid - [0.0, 0.0, half[2]]) / half  # box-normalised, in [-1, 1]^3
    rho = np.abs(p).max(axis=1)
    inner = rho > 1e-12
    dirs = np.zeros_like(p)
    dirs[inner] = p[inner] * half
    dirs[inner] /= np.linalg.norm(dirs[inner], axis=1, keepdims=True)
    reach = np.zeros(len(p))
    idx = np.flatnonzero(inner)
    reach[idx] = ray_exit_distance(c, dirs[idx], np.asarray(mesh.vertices), np.asarray(mesh.faces))
    if np.any(reach[idx] <= 0):
        raise ValueError("tetrahedralize: some rays from the bounding-box centre miss the surface; the body must be star-shaped")
    verts = c + (rho * reach)[:, None] * dirs
    verts = _smooth_interior(verts, tets)
    if tet_signed_volumes(verts, tets).min() <= 0:
        raise ValueError("tetrahedralize: the mapped grid has inverted tets; the body is too far from star-shaped")
    if volume_correct:
        v_tet = tet_signed_volumes(verts, tets).sum()
        verts = c + (verts - c) * (abs(mesh.volume) / v_tet) ** (1.0 / 3.0)
    return verts, tets


def _smooth_interior(verts: np.ndarray, tets: np.ndarray, iterations: int = 20) -> np.ndarray:
    """Laplacian smoothing of interior nodes (surface nodes stay on the surface).

    Central projection can fold the first interior layer under a strongly curved shoulder;
    moving interior nodes to their neighbours' mean unfolds it without touching the surface.
    """
    surface = np.unique(surface_of_tets(tets))
    interior = np.setdiff1d(np.arange(len(verts)), surface)
    edges = np.concatenate([tets[:, [a, b]] for a in range(4) for b in range(4) if a < b])
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    v = verts.copy()
    deg = np.bincount(edges.ravel(), minlength=len(v)).astype(np.float64)
    for _ in range(iterations):
        acc = np.zeros_like(v)
        np.add.at(acc, edges[:, 0], v[edges[:, 1]])
        np.add.at(acc, edges[:, 1], v[edges[:, 0]])
        v[interior] = acc[interior] / deg[interior, None]
    return v


def ray_exit_distance(origin: np.ndarray, dirs: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Distance from ``origin`` along each unit direction to the farthest surface crossing (Moller-Trumbore)."""
    tri = vertices[faces]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    out = np.zeros(len(dirs))
    for i, d in enumerate(dirs):
        pv = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, pv)
        ok = np.abs(det) > 1e-15
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tv = origin - tri[:, 0]
        u = np.einsum("ij,ij->i", tv, pv) * inv
        qv = np.cross(tv, e1)
        v = (qv @ d) * inv
        t = np.einsum("ij,ij->i", e2, qv) * inv
        hit = ok & (u >= -1e-12) & (v >= -1e-12) & (u + v <= 1 + 1e-12) & (t > 0)
        # The outermost crossing bounds the body (robust to grazing double hits at edges).
        out[i] = t[hit].max() if hit.any() else 0.0
    return out


def tet_quality(vertices: np.ndarray, tets: np.ndarray) -> dict:
    """Signed volumes and the normalised shape measure eta = 12 (3V)^(2/3) / sum(edge^2) (1 = regular)."""
    v = np.asarray(vertices, dtype=np.float64)
    vol = tet_signed_volumes(v, tets)
    e = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    l2 = sum(np.sum((v[tets[:, a]] - v[tets[:, b]]) ** 2, axis=1) for a, b in e)
    eta = 12.0 * np.cbrt(3.0 * np.abs(vol)) ** 2 / l2 * np.sign(vol)
    return {"min_volume": float(vol.min()), "total_volume": float(vol.sum()), "min_shape": float(eta.min()),
            "mean_shape": float(eta.mean()), "n_nodes": int(len(v)), "n_tets": int(len(tets))}


def embed_points(points: np.ndarray, vertices: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point, the tet containing it (or the nearest by centroid) and its barycentric weights.

    Visual surfaces and decorations are drawn deformed with the FEM body as
    ``sum_k w_k x[tets[i, k]]``; points slightly outside the tet mesh get extrapolated weights.
    """
    v = np.asarray(vertices, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64)
    a = v[tets[:, 0]]
    m = np.stack([v[tets[:, 1]] - a, v[tets[:, 2]] - a, v[tets[:, 3]] - a], axis=2)  # (T, 3, 3)
    m_inv = np.linalg.inv(m)
    centroids = v[tets].mean(axis=1)
    tet_idx = np.empty(len(pts), dtype=np.int32)
    weights = np.empty((len(pts), 4))
    for i, p in enumerate(pts):
        lam = np.einsum("tij,tj->ti", m_inv, p - a)
        bary = np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)
        # Prefer a containing tet (all weights >= 0); else the one whose worst weight is best.
        worst = bary.min(axis=1)
        j = int(np.argmax(worst)) if worst.max() >= -1e-9 else int(np.argmin(np.linalg.norm(centroids - p, axis=1)))
        tet_idx[i], weights[i] = j, bary[j]
    return tet_idx, weights


def vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Unit vertex normals (float32) of a triangle mesh: the area-weighted sum of the adjacent faces' normals."""
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    return (n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)).astype(np.float32)
