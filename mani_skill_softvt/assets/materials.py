"""Materials of the ten deformable assets and of their rigid twins, in one place (SI units).

| asset                | looks like                | rho kg/m3 |  E kPa | nu   | damping Pa*s | mu  |
|----------------------|---------------------------|-----------|--------|------|--------------|-----|
| soft_pastry001       | white swirled roll        | 250       | 80     | 0.25 | 1.0          | 0.9 |
| soft_pastry002       | panda-face steamed bun    | 300       | 70     | 0.30 | 1.0          | 0.9 |
| soft_pastry003       | small chocolate pastry    | 450       | 150    | 0.30 | 1.5          | 0.8 |
| soft_stw_cube_hq     | foam cube                 | 150       | 100    | 0.30 | 1.0          | 1.0 |
| soft_pastry005       | layered square pastry     | 350       | 100    | 0.25 | 1.0          | 0.8 |
| soft_stw_cylinder_hq | foam cylinder             | 150       | 100    | 0.30 | 1.0          | 1.0 |
| soft_pastry011       | golden brioche            | 280       | 80     | 0.25 | 1.0          | 0.9 |
| soft_stw_cuboid_hq   | golden block (bread-like) | 280       | 100    | 0.30 | 1.0          | 0.9 |
| soft_stw_sphere_hq   | foam ball                 | 150       | 120    | 0.35 | 1.0          | 1.0 |
| soft_pastry010       | pumpkin bun               | 320       | 90     | 0.30 | 1.0          | 0.9 |

Where the orders of magnitude come from (literature ranges, rounded; not fitted to data):
- Bread and bun crumb is a soft open-cell foam: apparent density ~200-350 kg/m3, compressive
  (Young's) modulus ~10-100 kPa depending on recipe and staling, Poisson ratio ~0.2-0.3. A whole
  baked piece with its crust is stiffer than its crumb: apparent moduli of tens to a few
  hundred kPa. We take 70-150 kPa, the upper part of that range, for a measured reason: at hex
  resolution 6 the Panda's 10 N grasp (and the x0.5 modulus OOD shift on top of it) must stay
  inside the FEM's valid range. With 25-40 kPa a binary close inverted tets under the pads
  (point-like contact on the ball, the rounded tops of the buns).
- Denser pastry (filled, chocolate-coated) is heavier (~400-500 kg/m3) and stiffer.
- Flexible polyurethane foam (the primitives): modulus ~10-200 kPa (we take 100-120 kPa), density 30-200 kg/m3;
  150 kg/m3 keeps the primitives' mass in the range of the pastries (10-20 g).
- Friction of bread/foam on rubber pads is high, ~0.8-1.0.
- ``damping`` is Newton's tet viscosity k_damp [Pa*s] on the strain rate; ~1 Pa*s gives a
  strain relaxation time k_damp/E ~ 10 us, enough to kill FEM ringing without creep.

Rigid twins share mesh, texture, density and therefore mass, and friction; they are PhysX rigid
bodies (no elastic constants), collided through a convex decomposition of the same surface
(``TWIN_MAX_CONVEX_PARTS`` coacd hulls at most). Earlier twins were FEM bodies x5 stiffer than
their soft asset: they still deformed (the expert's R_max had median 0.15) and cost 8 substeps.
"""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_TET_DAMPING = 1.0  # Pa*s
DEFAULT_OBJECT_FRICTION = 1.0

# asset id -> (density, youngs_modulus, poisson_ratio, damping, friction)
MATERIALS = {
    "soft_pastry001": (250.0, 8.0e+04, 0.25, 1.0, 0.9),
    "soft_pastry002": (300.0, 7.0e+04, 0.30, 1.0, 0.9),
    "soft_pastry003": (450.0, 1.5e+05, 0.30, 1.5, 0.8),
    "soft_stw_cube_hq": (150.0, 1.0e+05, 0.30, 1.0, 1.0),
    "soft_pastry005": (350.0, 1.0e+05, 0.25, 1.0, 0.8),
    "soft_stw_cylinder_hq": (150.0, 1.0e+05, 0.30, 1.0, 1.0),
    "soft_pastry011": (280.0, 8.0e+04, 0.25, 1.0, 0.9),
    "soft_stw_cuboid_hq": (280.0, 1.0e+05, 0.30, 1.0, 0.9),
    "soft_stw_sphere_hq": (150.0, 1.2e+05, 0.35, 1.0, 1.0),
    "soft_pastry010": (320.0, 9.0e+04, 0.30, 1.0, 0.9),
}

TWIN_MAX_CONVEX_PARTS = 8

# Props (rigid, simulated by SAPIEN; Newton sees them as colliders).
PROP_FRICTION = {"table": 0.6, "basket": 0.7, "plate": 0.5, "distractor": 0.6}


@dataclass(frozen=True)
class SoftMaterial:
    """Elastic material of a soft body (SI units). Pure data: the asset cards build it without
    importing the simulator (``physics.fem`` consumes it)."""

    youngs_modulus: float  # Pa
    poisson_ratio: float
    density: float  # kg/m^3
    damping: float = DEFAULT_TET_DAMPING  # Pa*s, viscous damping of the strain rate (VBD k_damp)
    friction: float = DEFAULT_OBJECT_FRICTION

    def __post_init__(self):
        if not self.youngs_modulus > 0:
            raise ValueError(f"Young's modulus must be > 0 Pa, got {self.youngs_modulus}")
        if not -1.0 < self.poisson_ratio < 0.5:
            raise ValueError(f"Poisson ratio must lie in (-1, 0.5), got {self.poisson_ratio}")
        if not self.density > 0:
            raise ValueError(f"density must be > 0 kg/m^3, got {self.density}")
        if self.damping < 0 or self.friction < 0:
            raise ValueError("damping and friction must be non-negative")
