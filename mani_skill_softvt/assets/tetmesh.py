"""Tetrahedral meshes for the FEM: structured box grids and tet-mesh surface extraction (pure numpy)."""

from __future__ import annotations

import itertools

import numpy as np

# Kuhn (Freudenthal) split of a hex into 6 tets sharing the main diagonal; neighbouring hexes
# agree on face diagonals, so the mesh is conforming.
_KUHN_PATHS = list(itertools.permutations(range(3)))


def tet_signed_volumes(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    v = np.asarray(vertices, dtype=np.float64)
    a, b, c, d = (v[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def box_tetmesh(size, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Structured tet mesh of a box of full ``size`` (m), origin at the centre of its bottom face.

    ``resolution`` cells along the longest side, the others proportional (at least one).
    Every tet is positively oriented.
    """
    size = np.asarray(size, dtype=np.float64)
    if size.shape != (3,) or np.any(size <= 0) or resolution < 1:
        raise ValueError(f"box_tetmesh needs 3 positive extents and resolution >= 1, got {size}, {resolution}")
    n = np.maximum(1, np.round(size / size.max() * resolution).astype(int))
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
