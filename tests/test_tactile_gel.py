"""The force-driven gel (tactile.gel) against contact mechanics, on analytic surfaces.

Rigid bodies: the gel is an elastic (Winkler) foundation of stiffness k per unit area. A rigid
sphere of radius R pressed with force F sinks it by d = sqrt(F / (k pi R)) over a disc of radius
a = sqrt(2 R d) (Johnson, Contact Mechanics 5.9); a flat face sinks it uniformly by F / (k A).
Deformable (FEM) bodies: the gel follows the contact pressure, which the simulator's penalty
contact makes proportional to the surface's overlap with the pad.
"""

import numpy as np
import pytest
import trimesh

from mani_skill_softvt.tactile import TactileSensor
from mani_skill_softvt.tactile import constants as C
from mani_skill_softvt.tactile.gel import balanced_indentation, foundation_stiffness, pressure_indentation
from mani_skill_softvt.tactile.geometry import contact_mask, contact_polygons, polygon_area, polygons_mask
from mani_skill_softvt.tactile.markers import flow_matrix, gel_flow

K = foundation_stiffness()
R = 0.01
SPHERE = trimesh.creation.icosphere(subdivisions=4, radius=R)


def touching(mesh: trimesh.Trimesh) -> np.ndarray:
    """Vertices moved so the lowest point just touches the gel plane (pad frame z = 0)."""
    v = np.asarray(mesh.vertices, np.float64)
    return v - [0.0, 0.0, v[:, 2].min()]


def moments(mask: np.ndarray) -> tuple[float, np.ndarray]:
    """Aspect ratio (major / minor standard deviation) of a pixel mask and its major axis (col, row)."""
    rows, cols = np.nonzero(mask)
    xy = np.c_[cols, rows].astype(float)
    ev, evec = np.linalg.eigh(np.cov((xy - xy.mean(0)).T))
    return float(np.sqrt(ev[1] / ev[0])), evec[:, 1]


def test_foundation_stiffness_is_the_confined_modulus_over_the_thickness():
    E, nu, h = C.GEL_MODULUS, C.GEL_POISSON, C.GEL_THICKNESS
    assert K == pytest.approx(E * (1 - nu) / ((1 + nu) * (1 - 2 * nu) * h))
    # Stiffer than a free layer (E / h): a bonded, nearly incompressible layer cannot bulge.
    assert K > 5 * E / h
    with pytest.raises(ValueError, match="Poisson"):
        foundation_stiffness(poisson=0.5)


@pytest.mark.parametrize("force", [0.5, 2.0, 8.0])
def test_rigid_sphere_sinks_the_gel_as_the_elastic_foundation_predicts(force):
    sensor = TactileSensor("left")
    ind, sink = sensor.indentation(touching(SPHERE), SPHERE.faces, normal_force=force, deformable=False)
    d = np.sqrt(force / (K * np.pi * R))  # 0.13-0.53 mm
    # The icosphere's flat facets lie inside the sphere, up to ~11 um at a face centre: the
    # surface stands further off the gel than the sphere would, so the gel must sink deeper by
    # up to that much to carry the same force; plus 1 % for summing over 0.118 mm grid pixels.
    facet_gap = R - np.linalg.norm(SPHERE.triangles_center, axis=1).min()
    assert 0.0 <= sink - d <= 1.5 * facet_gap + 0.01 * d
    # Deepest at the lowest point, which a pixel centre may miss by a facet's height.
    assert sink - facet_gap <= ind.max() <= sink
    # The gel carries exactly the force.
    assert K * ind.sum() * sensor.grid_pixel ** 2 == pytest.approx(force, rel=1e-9)
    # Contact disc: the 10 um threshold trims r^2 by 2R x 10 um (a 1-4 % smaller radius), plus
    # half a grid pixel of rim quantisation.
    radius = np.sqrt(contact_mask(ind).sum() / np.pi) * sensor.grid_pixel
    expected = np.sqrt(2 * R * (d - C.CONTACT_THRESHOLD))
    assert radius == pytest.approx(expected, abs=0.5 * sensor.grid_pixel + 0.02 * expected)
    # Round: equal second moments in every direction.
    assert moments(contact_mask(ind))[0] < 1.05


def test_patch_radius_grows_as_the_quarter_power_of_the_force():
    sensor = TactileSensor("left")
    forces = np.array([0.5, 1.0, 2.0, 4.0, 8.0])
    radii = [np.sqrt(contact_mask(sensor.indentation(touching(SPHERE), SPHERE.faces, f, deformable=False)[0]).sum())
             for f in forces]
    slope = np.polyfit(np.log(forces), np.log(radii), 1)[0]
    assert slope == pytest.approx(0.25, abs=0.02)


def test_a_flat_face_sinks_uniformly_over_exactly_its_area():
    box = trimesh.creation.box(extents=(8e-3, 6e-3, 4e-3))
    sensor = TactileSensor("left")
    force = 3.0
    ind, sink = sensor.indentation(touching(box), box.faces, force, deformable=False)
    mask = contact_mask(ind)
    area = 8e-3 * 6e-3
    assert sink == pytest.approx(force / (K * area), rel=0.03)  # pixel-quantised area: +-1 grid px per side
    assert mask.sum() * sensor.grid_pixel ** 2 == pytest.approx(area, rel=0.06)
    # A rectangle: it fills its bounding box, sides 8 and 6 mm.
    rows, cols = np.nonzero(mask)
    w, h = (np.ptp(cols) + 1) * sensor.grid_pixel, (np.ptp(rows) + 1) * sensor.grid_pixel
    assert mask.sum() / ((np.ptp(cols) + 1) * (np.ptp(rows) + 1)) > 0.98
    assert (w, h) == (pytest.approx(8e-3, abs=2 * sensor.grid_pixel), pytest.approx(6e-3, abs=2 * sensor.grid_pixel))
    assert np.ptp(ind[mask]) < 1e-9  # uniform


def test_a_cylinder_on_its_side_gives_a_stripe_along_its_axis():
    cyl = trimesh.creation.cylinder(radius=3e-3, height=12e-3, sections=64)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))  # axis along pad x
    ind, sink = TactileSensor("left").indentation(touching(cyl), cyl.faces, 2.0, deformable=False)
    aspect, axis = moments(contact_mask(ind))
    # Line contact on a foundation: F = k L 2 sqrt(2 R d) d (2/3): a stripe 12 mm long and
    # 2 sqrt(2 R d) wide; its aspect (std of a uniform length over that of a uniform width) is L / width.
    d = (3 * 2.0 / (4 * K * 12e-3 * np.sqrt(2 * 3e-3))) ** (2 / 3)
    width = 2 * np.sqrt(2 * 3e-3 * d)
    assert sink == pytest.approx(d, rel=0.05)
    assert aspect == pytest.approx(12e-3 / width, rel=0.15)
    assert abs(axis[0]) > 0.999  # along image columns (pad x)


def test_stiffness_shows_a_conforming_surface_gives_a_larger_shallower_patch_at_equal_force():
    # A soft sphere the pad has flattened (its cap cut off by the plane: the contact disc of the
    # FEM) against the rigid sphere, both at 4 N. Hertz: the contact radius scales as E*^(-1/3).
    # Here the soft object's own contact disc of radius a_s, from its Hertz solution with
    # E* = 137 kPa (the foam ball), is what the pad shows; the rigid one's is the gel's.
    force, E_soft = 4.0, 120e3 / (1 - 0.35 ** 2)
    a_soft = (3 * force * R / (4 * E_soft)) ** (1 / 3)  # 6.0 mm for R = 10 mm
    cut = R - np.sqrt(R * R - a_soft * a_soft)
    v = np.asarray(SPHERE.vertices, np.float64).copy()
    v[:, 2] = np.maximum(v[:, 2], -R + cut) + R - cut  # the cap pressed flat onto the plane z = 0
    v[:, 2] -= 2e-6  # the flattened face overlaps the pad a little, as FEM contacts do
    sensor = TactileSensor("left")
    soft, _ = sensor.indentation(v, SPHERE.faces, force, deformable=True)
    rigid, _ = sensor.indentation(touching(SPHERE), SPHERE.faces, force, deformable=False)
    ms, mr = contact_mask(soft), contact_mask(rigid)
    assert ms.sum() > 2 * mr.sum()
    assert soft.max() < 0.25 * rigid.max()
    # Radii in the ratio the two contact solutions give: the soft patch is the flattened disc
    # (its rim is where the last flattened vertex ring ends: up to one mesh edge inside a_soft);
    # the rigid one is the foundation's disc.
    edge = SPHERE.edges_unique_length.max()
    a_rigid = np.sqrt(2 * R * np.sqrt(force / (K * np.pi * R)))
    radius_soft = np.sqrt(ms.sum() / np.pi) * sensor.grid_pixel
    radius_rigid = np.sqrt(mr.sum() / np.pi) * sensor.grid_pixel
    assert a_soft - edge <= radius_soft <= a_soft + sensor.grid_pixel
    assert radius_soft / radius_rigid == pytest.approx(a_soft / a_rigid, rel=0.15)


def test_pressure_indentation_follows_the_overlap_and_carries_the_force():
    gap = np.full((40, 50), np.inf)
    gap[10:20, 10:30] = np.linspace(-2e-4, 0.0, 20)[None, :]  # overlap falls linearly to zero
    gap[25:30, 5:10] = 1e-4  # near but not touching
    ind = pressure_indentation(gap, 3.0, K, 1e-7)
    assert K * ind.sum() * 1e-7 == pytest.approx(3.0)
    ov = np.clip(-np.where(np.isfinite(gap), gap, 0), 0, None)
    np.testing.assert_allclose(ind, ov * ind.max() / ov.max(), rtol=1e-12)
    assert not ind[25:30, 5:10].any()
    # The cap bounds the overlap that counts; no force or no overlap: nothing.
    capped = pressure_indentation(gap, 3.0, K, 1e-7, overlap_cap=1e-4)
    assert np.ptp(capped[10:20, 10:20]) < 1e-12
    assert not pressure_indentation(gap, 0.0, K, 1e-8).any()
    assert not pressure_indentation(np.full((4, 4), 1e-3), 3.0, K, 1e-8).any()
    with pytest.raises(ValueError, match="finite"):
        pressure_indentation(gap, float("nan"), K, 1e-8)


def test_balanced_indentation_keeps_a_rigid_face_s_shape_past_the_plane():
    # A face tilted 0.2 deg (a cube twin's held face) that PhysX left 20 um past the pad: the gel
    # carries the force as it would if the face rested on the plane. The shape sets the patch:
    # strip width w = d / tan with d = sqrt(2 F tan / (K L)) (studies.twin_pinch.flat_face_patch).
    pixel, tilt, force = 0.1e-3, np.radians(0.2), 1.0
    x = (np.arange(160) + 0.5) * pixel
    resting = np.tile(x * np.tan(tilt), (100, 1))
    ind_rest, d_rest = balanced_indentation(resting, force, K, pixel ** 2)
    ind_past, d_past = balanced_indentation(resting - 20e-6, force, K, pixel ** 2)
    np.testing.assert_allclose(ind_past, ind_rest, rtol=0, atol=1e-12)
    assert d_past == pytest.approx(d_rest - 20e-6, abs=1e-12)
    d = np.sqrt(2 * force * np.tan(tilt) / (K * 100 * pixel))
    assert ind_rest.max() == pytest.approx(d, abs=np.tan(tilt) * pixel)
    assert (ind_rest[0] > 0).sum() * pixel == pytest.approx(d / np.tan(tilt), abs=pixel)


def test_balanced_indentation_bottoms_out_at_the_gel_travel():
    gap = np.zeros((10, 10))
    ind, d = balanced_indentation(gap, 1e6, K, 1e-8)
    assert np.all(ind == C.GEL_THICKNESS)
    ind, d = balanced_indentation(np.full((10, 10), np.inf), 5.0, K, 1e-8)
    assert not ind.any() and d == 0.0


def test_contact_polygons_are_the_exact_clipped_overlap():
    # A flat square 10 x 10 mm tilted so that one half lies past the plane: the overlap is a
    # 5 x 10 mm rectangle; clipped to a 4 mm half-width pad it is 4 x 10 mm... and 5 x 8 with hy = 4 mm.
    v = np.array([[-5e-3, -5e-3, 0.0], [5e-3, -5e-3, 0.0], [5e-3, 5e-3, 0.0], [-5e-3, 5e-3, 0.0]])
    v[:, 2] = v[:, 0] * 0.1  # z < 0 for x < 0
    f = np.array([[0, 1, 2], [0, 2, 3]])
    polys = contact_polygons(v, f, (10e-3, 4e-3))
    assert sum(polygon_area(p) for p in polys) == pytest.approx(5e-3 * 8e-3, rel=1e-9)
    mask = polygons_mask(polys)
    assert mask.sum() * C.PIXEL_SIZE ** 2 == pytest.approx(40e-6, rel=0.03)


# ------------------------------------------------------------------ markers: the gel's outward flow


def test_gel_flow_conserves_the_pressed_volume_around_a_uniform_disc():
    # A disc of radius a pressed uniformly w0 into a layer of thickness h. Mass conservation with a
    # potential flow: the mean lateral displacement is w0 r / (2 h) inside the disc and
    # V / (2 pi h r) outside (all of V = pi a^2 w0 crossing the circle of radius r through the
    # layer's thickness); the surface moves 1.5x the mean (parabolic profile). Tolerances: the
    # pooled cells (4 px) against a 20 px disc: 3 % outside it; inside, a point 1.5 cells from the
    # centre sees the cells' discreteness, 8 % and 6 deg.
    rows, cols = np.mgrid[0:120, 0:160]
    a, w0, h = 20.0, 50e-6, C.GEL_THICKNESS
    ind = np.where(np.hypot(cols - 80.5, rows - 60.5) <= a, w0, 0.0)
    volume = ind.sum()  # m x px^2
    for r in (6.0, 10.0, 14.0, 26.0, 40.0, 58.0):
        for direction in ((1, 0), (0, 1), (-0.6, 0.8)):
            point = np.array([[80.5, 60.5]]) + r * np.array(direction)
            u = gel_flow(ind, point, h)[0]
            mean = w0 * r / (2 * h) if r < a else volume / (2 * np.pi * h * r)
            assert u @ direction == pytest.approx(C.FLOW_SURFACE_FACTOR * mean, rel=0.08 if r < a else 0.03), (r, direction)
            assert abs(u[0] * direction[1] - u[1] * direction[0]) < np.sin(np.deg2rad(6)) * np.linalg.norm(u)  # radial
    # Linear in the indentation, zero without it, and the same with a prebuilt matrix.
    point = np.array([[120.0, 30.0]])
    np.testing.assert_allclose(gel_flow(2 * ind, point, h), 2 * gel_flow(ind, point, h))
    assert not gel_flow(np.zeros_like(ind), point, h).any()
    np.testing.assert_array_equal(gel_flow(ind, point, h, matrix=flow_matrix(point, ind.shape, h)), gel_flow(ind, point, h))


@pytest.mark.parametrize("deformable", [True, False])
def test_markers_dilate_outward_and_more_with_more_force(deformable):
    # A rigid sphere pressed onto the gel with growing force (the gel conforms: balanced
    # indentation), or the same sphere's overlap with the pad carrying the force (pressure
    # indentation, as for an FEM body). The pressed volume is F / K either way, so the markers
    # outside the patch move outward by ~1.5 F / (2 pi h K r), proportional to the force.
    sensor = TactileSensor("left")
    centre = np.array([(C.IMAGE_WIDTH - 1) / 2, (C.IMAGE_HEIGHT - 1) / 2])
    verts = touching(SPHERE) - [0.0, 0.0, 0.3e-3 if deformable else 0.0]
    faces = np.asarray(SPHERE.faces)
    means = []
    for force in (1.0, 2.0, 4.0, 8.0):
        sensor.reset()
        frame = sensor.render_local(verts, faces, normal_force=force, deformable=deformable)
        rel = frame.marker_initial - centre
        r = np.maximum(np.linalg.norm(rel, axis=1), 1e-9)  # the centre marker is not outside
        move = frame.marker_current - frame.marker_initial
        radial = (move * rel).sum(1) / r
        outside = r > 1.2 * np.sqrt(frame.contact.sum() / np.pi)
        assert outside.sum() >= 40
        assert (radial[outside] > 0).all()
        expected = C.FLOW_SURFACE_FACTOR * force / K / (2 * np.pi * C.GEL_THICKNESS * (r * C.PIXEL_SIZE)) / C.PIXEL_SIZE
        np.testing.assert_allclose(radial[outside], expected[outside], rtol=0.1)
        means.append(radial[outside].mean())
    assert all(b > a for a, b in zip(means, means[1:]))
