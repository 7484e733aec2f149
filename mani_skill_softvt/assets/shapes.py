"""Procedural, watertight object shapes (pure numpy; deterministic).

Every body is a deformed sphere: a (latitude x longitude) grid of directions mapped to points
by a shape function, closed with one vertex at each pole. That topology is watertight by
construction, and one generator covers all ten objects: superellipsoids give the cube, cuboid,
cylinder and ball; radial and height modulations give the swirl, the layers and the lobes.

Decorations (panda ears and eyes, a pumpkin stem) are small separate closed meshes that sit on
the body; they are drawn deformed with the body (barycentric embedding) but are not simulated.

Frame: metres, z up, origin at the centre of the bottom face of the bounding box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

N_LAT = 14  # latitude rings (poles excluded): ~300 surface vertices per body
N_LON = 24


def _signed_pow(x, e):
    return np.sign(x) * np.abs(x) ** e


def sphere_grid(n_lat: int = N_LAT, n_lon: int = N_LON):
    """Directions (eta = latitude in (-pi/2, pi/2), omega = longitude) and closed triangle faces."""
    eta = np.linspace(-np.pi / 2, np.pi / 2, n_lat + 2)[1:-1]
    omega = np.linspace(-np.pi, np.pi, n_lon, endpoint=False)
    e, w = np.meshgrid(eta, omega, indexing="ij")  # (n_lat, n_lon)
    faces = []
    ring = lambda i, j: 1 + i * n_lon + (j % n_lon)  # noqa: E731  (vertex 0 = south pole)
    north = 1 + n_lat * n_lon
    for j in range(n_lon):
        faces.append((0, ring(0, j + 1), ring(0, j)))
        faces.append((north, ring(n_lat - 1, j), ring(n_lat - 1, j + 1)))
    for i in range(n_lat - 1):
        for j in range(n_lon):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            faces += [(a, b, d), (a, d, c)]
    return e.ravel(), w.ravel(), np.asarray(faces, dtype=np.int32)


def superellipsoid(half: tuple[float, float, float], e_vert: float, e_horiz: float, modulate=None,
                   n_lat: int = N_LAT, n_lon: int = N_LON):
    """Closed superellipsoid surface with half-extents ``half``.

    ``e_vert``/``e_horiz`` are the squareness exponents (0.1 ~ box edges, 1 = round).
    ``modulate(eta, omega) -> (radial_scale, dz)`` perturbs the shape (swirls, layers, lobes).
    Returns vertices (N, 3) with the bottom at z = 0 and faces (F, 3), outward-oriented.
    """
    eta, omega, faces = sphere_grid(n_lat, n_lon)
    ce, se = np.cos(eta), np.sin(eta)
    x = half[0] * _signed_pow(ce, e_vert) * _signed_pow(np.cos(omega), e_horiz)
    y = half[1] * _signed_pow(ce, e_vert) * _signed_pow(np.sin(omega), e_horiz)
    z = half[2] * _signed_pow(se, e_vert)
    if modulate is not None:
        s, dz = modulate(eta, omega)
        x, y, z = x * s, y * s, z + dz
    poles = np.array([[0.0, 0.0, -half[2]], [0.0, 0.0, half[2]]])
    if modulate is not None:
        s0, dz0 = modulate(np.array([-np.pi / 2, np.pi / 2]), np.zeros(2))
        poles[:, 2] += dz0
    v = np.concatenate([poles[:1], np.stack([x, y, z], axis=1), poles[1:]])
    v[:, 2] -= v[:, 2].min()
    return v, faces


@dataclass(frozen=True)
class Part:
    """A closed triangle mesh with one colour (RGBA)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    color: tuple[float, float, float, float]


def _ellipsoid(center, half, n_lat=6, n_lon=10):
    v, f = superellipsoid(half, 1.0, 1.0, n_lat=n_lat, n_lon=n_lon)
    v = v - [0.0, 0.0, half[2]] + np.asarray(center)
    return v, f


# ---------------------------------------------------------------------------------- the ten bodies
def swirl_bun():
    """White swirled pastry: a domed bun whose top carries a three-arm spiral ridge."""
    def mod(eta, omega):
        up = np.clip(np.sin(eta), 0.0, 1.0)
        spiral = np.sin(3.0 * omega + 9.0 * (1.0 - up))
        return 1.0 + 0.04 * up * spiral, 0.0 * up
    return superellipsoid((0.030, 0.030, 0.015), 0.7, 1.0, mod)


def panda_bun():
    """Panda-face pastry: a white round bun; ears, eye patches and nose are decorations."""
    return superellipsoid((0.029, 0.029, 0.016), 0.7, 1.0)


def panda_decorations(body_v):
    top = body_v[:, 2].max()
    black = (0.05, 0.05, 0.05, 1.0)
    parts = []
    for side in (-1, 1):
        v, f = _ellipsoid((0.004, side * 0.017, top - 0.006), (0.006, 0.006, 0.006))
        parts.append(Part(f"ear_{'left' if side > 0 else 'right'}", v, f, black))
        v, f = _ellipsoid((0.019, side * 0.009, top - 0.012), (0.006, 0.0045, 0.0055))
        parts.append(Part(f"eye_{'left' if side > 0 else 'right'}", v, f, black))
    v, f = _ellipsoid((0.026, 0.0, top - 0.019), (0.003, 0.004, 0.003))
    parts.append(Part("nose", v, f, black))
    return parts


def chocolate_bar():
    """Small chocolate rectangular pastry: a rounded slab, 60 x 34 x 24 mm."""
    return superellipsoid((0.030, 0.017, 0.012), 0.25, 0.25)


def soft_cube():
    """Soft cream-colored cube, 45 mm, slightly rounded edges."""
    return superellipsoid((0.0225, 0.0225, 0.0225), 0.2, 0.2)


def layered_square():
    """Yellow square layered pastry: a square block with three horizontal layers (grooves)."""
    def mod(eta, omega):
        layers = np.cos(np.pi * 3.0 * (np.sin(eta) + 1.0))
        return 1.0 - 0.035 * (1.0 + layers) * np.cos(eta) ** 2, 0.0 * eta
    return superellipsoid((0.025, 0.025, 0.017), 0.3, 0.25, mod, n_lat=18)


def soft_cylinder():
    """Soft tan cylinder standing upright: 44 mm diameter, 50 mm tall."""
    return superellipsoid((0.022, 0.022, 0.025), 0.2, 1.0)


def golden_pastry():
    """Golden pastry: an oval, plump bun 62 x 40 x 30 mm."""
    return superellipsoid((0.031, 0.020, 0.015), 0.6, 0.9)


def golden_block():
    """Cream/golden rectangular block (the paper's soft_stw_cuboid_hq): 60 x 34 x 30 mm."""
    return superellipsoid((0.030, 0.017, 0.015), 0.2, 0.2)


def soft_ball():
    """Soft red ball, 48 mm diameter."""
    return superellipsoid((0.024, 0.024, 0.024), 1.0, 1.0, n_lat=12, n_lon=20)


def pumpkin():
    """Orange pumpkin-shaped pastry: a squat sphere with eight lobes, 62 mm wide, 40 mm tall."""
    def mod(eta, omega):
        return 1.0 + 0.05 * np.cos(8.0 * omega) * np.cos(eta) ** 4, 0.0 * eta
    return superellipsoid((0.029, 0.029, 0.020), 0.85, 1.0, mod, n_lon=32)


def pumpkin_decorations(body_v):
    top = body_v[:, 2].max()
    v, f = superellipsoid((0.0035, 0.0035, 0.005), 0.3, 1.0, n_lat=4, n_lon=8)
    v = v + [0.0, 0.0, top - 0.003]
    return [Part("stem", v, f, (0.25, 0.45, 0.15, 1.0))]




# asset id -> (body generator, decorations generator or None, body colour)
BODIES = {
    "soft_pastry001": (swirl_bun, None, (0.96, 0.94, 0.89, 1.0)),
    "soft_pastry002": (panda_bun, panda_decorations, (0.97, 0.97, 0.95, 1.0)),
    "soft_pastry003": (chocolate_bar, None, (0.33, 0.18, 0.09, 1.0)),
    "soft_stw_cube_hq": (soft_cube, None, (0.95, 0.90, 0.76, 1.0)),
    "soft_pastry005": (layered_square, None, (0.97, 0.83, 0.30, 1.0)),
    "soft_stw_cylinder_hq": (soft_cylinder, None, (0.80, 0.66, 0.48, 1.0)),
    "soft_pastry011": (golden_pastry, None, (0.86, 0.60, 0.20, 1.0)),
    "soft_stw_cuboid_hq": (golden_block, None, (0.93, 0.80, 0.52, 1.0)),
    "soft_stw_sphere_hq": (soft_ball, None, (0.85, 0.10, 0.10, 1.0)),
    "soft_pastry010": (pumpkin, pumpkin_decorations, (0.95, 0.50, 0.10, 1.0)),
}


def object_parts(asset_id: str) -> tuple[Part, list[Part]]:
    """(body, decorations) of a soft asset."""
    body_fn, deco_fn, color = BODIES[asset_id]
    v, f = body_fn()
    body = Part("body", v, f, color)
    return body, (deco_fn(v) if deco_fn else [])
