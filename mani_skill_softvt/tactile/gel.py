"""The gel as pure functions: how far the GelSight's elastomer is pushed in, given what presses it.

Gap maps (pad frame, see :mod:`.geometry`) hold the object surface's height above the undeformed
gel plane per pixel, +inf where nothing is within reach. Three situations:

- **Prescribed geometry** (:func:`geometric_indentation`): a rigid indenter moved to a known
  pose; the gel takes its shape wherever it reaches past the plane, ``clip(-gap, 0, travel)``
  (the unit tests' spheres).
- **A deformable (FEM) object pressed with a known force** (:func:`pressure_indentation`). The
  simulator's pad is rigid and its contact is a penalty: where the object's surface overlaps the
  pad, the overlap is the contact pressure's footprint (a node's force is stiffness x overlap).
  The gel, in series with that contact, sinks in proportion to the pressure,
  ``indentation = p / k``, with the pressure field ``p ~ overlap`` scaled so that it carries the
  pad's simulated normal force F: ``k * sum(indentation) * pixel_area = F``. The patch is where
  the object touches the pad, its depth map the pressure distribution (edge-loaded under a flat
  face, domed under a round one).
- **A rigid object pressed with a known force** (:func:`balanced_indentation`). Its surface
  cannot deform, so the gel alone conforms: it sinks by a common depth d wherever the object is
  within d of the plane, ``indentation = clip(d - gap, 0, travel)``, with d chosen so that the
  gel carries F. A sphere gives a disc whose radius grows as F^(1/4) (F = k pi R d^2, a^2 = 2 R d).
  Where the simulator left the body a little past the plane (PhysX's contact slop, tens of
  micrometres) its surface keeps its shape: the load depends on the shape and the force, not on
  where the rigid solver stopped (clamping the gap at the plane flattened a face tilted 0.2 degrees
  into a level one).

The gel itself is a thin layer bonded to a rigid backing: an elastic (Winkler) foundation of
stiffness ``k = (1 - nu) E / ((1 + nu)(1 - 2 nu) h)`` per unit area (Johnson, *Contact
Mechanics*, section 5.9; constants and their sources in :mod:`.constants`). Why a foundation and
not a Hertz half-space: the Mini's gel is ~2 mm thick on rigid acrylic, thinner than most grasp
contacts (5-15 mm), the regime where a thin layer's response is local. The gel is stiffer than
the foods and foams (0.3 MPa against 70-150 kPa), so on a soft object it sinks tens of
micrometres and the object does the deforming, as on a real sensor.

What it leaves out: the layer's lateral coupling (a real gel also sinks a little just outside
the contact; the optics' membrane spreading stands in for it), friction's effect on depth, and
the gel's own push back on the simulated object (the simulator's pad is rigid).
"""

from __future__ import annotations

import numpy as np

from . import constants as C


def foundation_stiffness(modulus: float = C.GEL_MODULUS, thickness: float = C.GEL_THICKNESS,
                         poisson: float = C.GEL_POISSON) -> float:
    """Winkler stiffness (Pa per m of indentation) of a thin elastic layer bonded to a rigid base:
    its confined (uniaxial-strain) modulus over its thickness."""
    if not (modulus > 0 and thickness > 0 and 0.0 <= poisson < 0.5):
        raise ValueError(f"gel modulus and thickness must be positive and Poisson's ratio in [0, 0.5), got "
                         f"{modulus!r}, {thickness!r}, {poisson!r}")
    return (1.0 - poisson) * modulus / ((1.0 + poisson) * (1.0 - 2.0 * poisson) * thickness)


def footprint_mask(height: int, width: int, pixel: float, half_extents) -> np.ndarray:
    """Boolean (H, W): pixel centres over the pad's gel, a rectangle of ``half_extents`` (x, y)
    metres about the image centre. Outside it there is no gel to press (the finger's edge)."""
    hx, hy = half_extents
    xs = (np.arange(width) + 0.5 - width / 2) * pixel
    ys = (np.arange(height) + 0.5 - height / 2) * pixel
    return (np.abs(ys)[:, None] <= hy) & (np.abs(xs)[None, :] <= hx)


def geometric_indentation(gap: np.ndarray, travel: float = C.GEL_THICKNESS) -> np.ndarray:
    """Indentation (m) where the object's surface lies past the gel plane: clip(-gap, 0, travel)."""
    g = np.asarray(gap, np.float64)
    return np.clip(-np.where(np.isfinite(g), g, 0.0), 0.0, travel)


def pressure_indentation(gap: np.ndarray, force: float, stiffness: float, pixel_area: float,
                         overlap_cap: float | None = None, travel: float = C.GEL_THICKNESS) -> np.ndarray:
    """Indentation map (m) of the gel under a deformable object's contact pressure (module
    docstring): proportional to the surface's overlap with the pad, ``clip(-gap, 0, cap)``, and
    carrying ``force`` (N). ``overlap_cap`` bounds the overlap (see the sensor: between FEM nodes
    the linear surface may dip further than any node does). No force or no overlap: zeros."""
    g = np.asarray(gap, np.float64)
    if not np.isfinite(force):
        raise ValueError(f"pad normal force must be finite, got {force!r}")
    overlap = np.clip(-np.where(np.isfinite(g), g, 0.0), 0.0, np.inf if overlap_cap is None else overlap_cap)
    total = overlap.sum()
    if force <= 0.0 or total <= 0.0:
        return np.zeros_like(g)
    scale = force / (stiffness * pixel_area * total)
    return np.minimum(overlap * scale, travel)


def _load(g: np.ndarray, d: float, travel: float) -> float:
    """Sum over pixels of clip(d - g, 0, travel)."""
    return float(np.clip(d - g, 0.0, travel).sum())


def balanced_indentation(gap: np.ndarray, force: float, stiffness: float, pixel_area: float,
                         travel: float = C.GEL_THICKNESS) -> tuple[np.ndarray, float]:
    """Indentation map (m) of a Winkler gel pressed with normal ``force`` (N) by the surface whose
    ``gap`` map is given, and the gel's common sink depth d (m; module docstring).

    No force, or no surface within reach, gives no indentation (d = 0). A force the gel cannot
    carry within its travel bottoms it out: the indentation is the travel wherever the surface is.
    """
    g = np.asarray(gap, np.float64)
    out = np.zeros_like(g)
    if not np.isfinite(force):
        raise ValueError(f"pad normal force must be finite, got {force!r}")
    finite = np.isfinite(g)
    if force <= 0.0 or not finite.any():
        return out, 0.0
    target = force / (stiffness * pixel_area)  # sum of indentations over pixels (m)
    vals = g[finite]  # not clamped at the plane (module docstring)
    # Only pixels within one travel of the closest point can carry load before it bottoms out.
    near = np.sort(vals[vals < vals.min() + travel])
    # Without the travel clamp the load is piecewise linear in d with kinks at the sorted gaps:
    # at d = near[j] it is j * near[j] - sum(near[:j]); solve on the segment that reaches target.
    csum = np.cumsum(near)
    n = np.arange(1, len(near) + 1)
    load_at = n[:-1] * near[1:] - csum[:-1]  # load at d = near[j + 1], j + 1 pixels engaged
    j = int(np.searchsorted(load_at, target))  # j + 1 pixels engaged
    d = (target + csum[j]) / (j + 1)
    if d - near[0] > travel:
        # Deepest pixel bottomed out: the load is still monotone in d; bisect it with the clamp.
        if target >= travel * finite.sum():
            out[finite] = travel
            return out, float(vals.min() + travel)
        lo, hi = near[0], vals.max() + travel
        for _ in range(64):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _load(vals, mid, travel) < target else (lo, mid)
        d = 0.5 * (lo + hi)
    out[finite] = np.clip(d - vals, 0.0, travel)
    return out, float(d)
