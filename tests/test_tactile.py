"""GelSight Mini sensor: contact geometry, optics and markers against physical expectations.

Scenes are a rigid sphere (trimesh icosphere, R = 10 mm) pressed into the gel; in the pad frame
the gel surface is z = 0 and the object sits on the +z side, so "pressed d" means the sphere's
lowest point is at z = -d.
"""

from importlib import resources

import cv2
import numpy as np
import pytest
import trimesh

from mani_skill_softvt.physics.transforms import planar_rigid_fit
from mani_skill_softvt.tactile import TactileFrame, TactileSensor, finger_pad_frame
from mani_skill_softvt.tactile import constants as C
from mani_skill_softvt.tactile.geometry import (contact_area, contact_centroid, contact_mask,
                                                heightmap_from_triangles, pixel_centers,
                                                to_pixels)
from mani_skill_softvt.tactile.markers import gel_flow, marker_displacements, marker_grid
from mani_skill_softvt.tactile.optics import load_optics, render_image

R = 0.01  # sphere radius (m)
SPHERE = trimesh.creation.icosphere(subdivisions=4, radius=R)  # 5120 faces, edges ~0.6 mm
FACES = np.asarray(SPHERE.faces)


def sphere(depth: float, x: float = 0.0, y: float = 0.0) -> np.ndarray:
    """Sphere vertices in the pad frame, pressed ``depth`` into the gel with its centre over (x, y)."""
    return np.asarray(SPHERE.vertices) + [x, y, R - depth]


def rotate_z(points: np.ndarray, theta: float, about=(0.0, 0.0)) -> np.ndarray:
    """Rotate points about the pad normal (+z) through ``about`` by ``theta`` (from +x towards +y)."""
    c, s = np.cos(theta), np.sin(theta)
    p = points.copy()
    p[:, :2] = (points[:, :2] - about) @ np.array([[c, s], [-s, c]]) + about
    return p


def test_sphere_press_gives_the_geometric_contact_disc_centred_under_it():
    d, x, y = 0.5e-3, 1.2e-3, -0.7e-3
    frame = TactileSensor("left").render_local(sphere(d, x, y), FACES)
    assert isinstance(frame, TactileFrame)
    # A rigid sphere pressed d into a plane cuts a disc of radius sqrt(2 R d - d^2) (~sqrt(2 R d)).
    expected = np.sqrt(2 * R * d - d * d)  # 3.15 mm = 53 px
    radius = np.sqrt(contact_area(frame.depth) / np.pi)
    # Tolerance 4 %, the sum of: the icosphere's flat facets sit inside the sphere (sagitta
    # e^2 / 8R ~ 5 um of the 500 um press: -0.5 % on the radius); the 10 um contact threshold
    # (-1 %); pixel quantisation of the rim (+-0.5 px of 53 px: 1 %); margin.
    assert radius == pytest.approx(expected, rel=0.04)
    # It is a disc: every contact pixel lies within the radius (+1 px) of the centroid.
    centre = contact_centroid(frame.depth)
    rows, cols = np.nonzero(contact_mask(frame.depth))
    assert np.hypot(cols - centre[0], rows - centre[1]).max() <= expected / C.PIXEL_SIZE + 1.0
    # Centred where the sphere centre projects, within 1 px.
    np.testing.assert_allclose(centre, to_pixels(np.array([x, y])), atol=1.0)
    # The penetration profile is the sphere's cap, d - (R - sqrt(R^2 - r^2)), up to the mesh's
    # facets, which lie inside the sphere by at most the gap at a face centre (~11 um here).
    xs, ys = pixel_centers()
    X, Y = np.meshgrid(xs - x, ys - y)
    cap = d - (R - np.sqrt(np.maximum(R * R - X**2 - Y**2, 0.0)))
    inner = cap > 0.2 * d
    facet_gap = R - np.linalg.norm(SPHERE.triangles_center, axis=1).min()
    err = frame.depth[inner] - cap[inner]
    assert err.max() < 1e-7 and err.min() > -1.1 * facet_gap
    assert frame.depth.max() == pytest.approx(d, rel=0.02)
    # Optics: the press changes the image, and only around the contact.
    bg = load_optics().background
    change = np.abs(render_image(frame.depth).astype(int) - bg).sum(axis=2) > 0
    assert change[inner].mean() > 0.5
    far = np.hypot(X, Y) > 2 * expected
    assert not change[far].any()


def test_no_contact_gives_exactly_the_background_and_markers_at_rest():
    calib = load_optics()
    # The background is taxim's own GelSight Mini frame (BGR on disk), 2x2-averaged to 320 x 240.
    with resources.as_file(resources.files("taxim") / "calib" / "gelsight_mini" / "dataPack.npz") as path:
        f0 = np.load(path, allow_pickle=True)["f0"]
    assert np.array_equal(calib.background, cv2.resize(f0[..., ::-1], (320, 240), interpolation=cv2.INTER_AREA))
    zero = np.zeros((C.IMAGE_HEIGHT, C.IMAGE_WIDTH))
    img = render_image(zero)
    assert img.dtype == np.uint8 and img.shape == (240, 320, 3)
    assert np.array_equal(img, calib.background)

    sensor = TactileSensor("left")
    for frame in (sensor.render_local(sphere(-1e-3), FACES),  # 1 mm above the gel
                  sensor.render_local(sphere(0.8e-3), FACES),  # pressed ...
                  sensor.render_local(sphere(-1e-3, 0.5e-3), FACES)):  # ... and released, moved
        pass
    assert np.array_equal(frame.image, sensor.background_frame)
    assert np.array_equal(frame.marker_current, frame.marker_initial)
    assert np.array_equal(frame.depth, zero)
    assert frame.image.shape == (240, 320, 3) and frame.image.dtype == np.uint8
    assert frame.marker_initial.shape == (99, 2) and frame.marker_initial.dtype == np.float32
    assert np.array_equal(marker_displacements(sensor.marker_initial, zero, (3.0, 1.0), 0.2), sensor.marker_initial)


def test_shear_moves_markers_under_the_contact_and_not_far_away():
    sensor = TactileSensor("left")
    x0 = -4e-3  # contact on the left of the pad, so the right side is far from it
    sensor.render_local(sphere(0.8e-3, x=x0), FACES)  # contact onset
    pressed = sensor.render_local(sphere(0.8e-3, x=x0), FACES)
    shift = np.array([0.3e-3, 0.2e-3])  # tangential translation of the (stuck) sphere
    sheared = sensor.render_local(sphere(0.8e-3, x=x0 + shift[0], y=shift[1]), FACES)
    # The press moved with the sphere, and its outward flow (the dilation) with it: the shear is
    # what the markers moved beyond the change of that flow.
    k = sensor.downsample

    def flow(verts):
        return k * gel_flow(sensor.indentation(verts, FACES)[0], sensor.marker_grid_xy, matrix=sensor.marker_flow)

    move = (sheared.marker_current - pressed.marker_current
            - (flow(sphere(0.8e-3, x=x0 + shift[0], y=shift[1])) - flow(sphere(0.8e-3, x=x0))))
    dist = np.linalg.norm(pressed.marker_initial - to_pixels(np.array([x0, 0.0])), axis=1)
    radius_px = np.sqrt(2 * R * 0.8e-3) / C.PIXEL_SIZE  # 68 px
    under, far = dist < 0.5 * radius_px, dist > 150
    assert under.sum() >= 3 and far.sum() >= 20
    # Under the contact the gel follows the patch: +x, +y of the pad = +col, +row of the image.
    expected = shift / C.PIXEL_SIZE  # (5.1, 3.4) px
    np.testing.assert_allclose(move[under], np.broadcast_to(expected, move[under].shape), atol=0.15 * np.linalg.norm(expected))
    assert np.abs(move[far]).max() < 0.1
    assert not np.array_equal(sheared.image, pressed.image)


def test_pressing_deeper_never_shrinks_the_contact():
    depths = np.linspace(0.05e-3, 1.9e-3, 15)
    areas = [contact_area(heightmap_from_triangles(sphere(d), FACES)) for d in depths]
    assert all(b >= a for a, b in zip(areas, areas[1:]))
    assert areas[-1] > 10 * areas[0]
    # ... and the indentation images get stronger (mean colour change grows).
    bg = load_optics().background.astype(int)
    change = [np.abs(render_image(heightmap_from_triangles(sphere(d), FACES)).astype(int) - bg).mean() for d in depths[::3]]
    assert all(b > a for a, b in zip(change, change[1:]))


def test_left_and_right_fingers_are_mirror_images():
    # Both pads squeeze one sphere from opposite sides of the hand's y axis; the contact is off
    # the pads' centres along the hand's x and z, so the mirroring is visible.
    hand_x, hand_y, hand_z = np.eye(3)
    centre = np.array([2.5e-3, 0.0, 1.5e-3])
    gap = R - 0.6e-3  # each pad's gel plane 0.6 mm inside the sphere
    left, right = TactileSensor("left"), TactileSensor("right")
    pose_l = left.pad_pose(np.array([0.0, -gap, 0.0]), hand_y, hand_x)  # faces +y, towards the right finger
    pose_r = right.pad_pose(np.array([0.0, gap, 0.0]), -hand_y, hand_x)
    np.testing.assert_allclose(pose_r, finger_pad_frame("right", np.array([0.0, gap, 0.0]), -hand_y, hand_x))
    world = np.asarray(SPHERE.vertices) + centre
    fl, fr = left.render(world, FACES, pose_l), right.render(world, FACES, pose_r)
    # Same world contact: the right depth map is the left one flipped horizontally (left-right).
    np.testing.assert_allclose(fr.depth, fl.depth[:, ::-1], atol=1e-9)
    cl, cr = contact_centroid(fl.depth), contact_centroid(fr.depth)
    assert cl[0] - (C.IMAGE_WIDTH - 1) / 2 == pytest.approx(2.5e-3 / C.PIXEL_SIZE, abs=1.0)  # left: +hand x is right
    assert cr[0] - (C.IMAGE_WIDTH - 1) / 2 == pytest.approx(-2.5e-3 / C.PIXEL_SIZE, abs=1.0)  # right: on the left
    assert cl[1] == pytest.approx(cr[1], abs=1e-6)  # same rows: both images have the same "up" ...
    assert cl[1] < (C.IMAGE_HEIGHT - 1) / 2 - 10  # ... +hand z is up (row < centre) in both
    # Markers: the right field is the left one mirrored (the rest grid is mirror-symmetric).
    grid = marker_grid()
    mirror = np.lexsort((C.IMAGE_WIDTH - 1 - grid[:, 0], grid[:, 1]))  # index of each marker's mirror twin
    np.testing.assert_allclose(grid[mirror], np.c_[C.IMAGE_WIDTH - 1 - grid[:, 0], grid[:, 1]], atol=1e-9)
    disp_l = fl.marker_current - fl.marker_initial
    disp_r = fr.marker_current - fr.marker_initial
    assert np.abs(disp_l).max() > 0.5
    np.testing.assert_allclose(disp_r[mirror], disp_l * [-1, 1], atol=1e-3)
    # Images: the same sensor model (lighting fixed in each sensor's own frame), so the colours
    # differ, but the changed region is the mirror image.
    bg = right.background_frame.astype(int)
    changed_l = np.abs(fl.image.astype(int) - bg).sum(axis=2) > 3
    changed_r = np.abs(fr.image.astype(int) - bg).sum(axis=2) > 3
    iou = (changed_r & changed_l[:, ::-1]).sum() / (changed_r | changed_l[:, ::-1]).sum()
    assert iou > 0.85


def test_twist_rotates_markers_about_the_contact_centre_in_the_right_sense():
    sensor = TactileSensor("left")
    verts = sphere(1.0e-3)
    sensor.render_local(verts, FACES)  # onset
    base = sensor.render_local(verts, FACES)
    theta = np.deg2rad(3.0)  # positive: from +x (cols) towards +y (rows)
    twisted = sensor.render_local(rotate_z(verts, theta), FACES)
    centre = to_pixels(np.zeros(2))
    rel = base.marker_initial - centre
    move = twisted.marker_current - base.marker_current
    r = np.linalg.norm(rel, axis=1)
    under = (r > 5) & (r < 0.8 * np.sqrt(2 * R * 1e-3) / C.PIXEL_SIZE)
    assert under.sum() >= 4
    # A rigid rotation by theta moves a marker at lever arm rel by theta * (-rel_y, rel_x).
    expected = theta * np.c_[-rel[:, 1], rel[:, 0]]
    np.testing.assert_allclose(move[under], expected[under], atol=0.2 * theta * r[under].max())
    # Sense: the marker right of the centre (+col) moves down (+row), the one left of it up.
    right_of = under & (np.abs(rel[:, 1]) < 1) & (rel[:, 0] > 0)
    left_of = under & (np.abs(rel[:, 1]) < 1) & (rel[:, 0] < 0)
    assert right_of.any() and left_of.any()
    assert (move[right_of, 1] > 0).all() and (move[left_of, 1] < 0).all()
    # The 2-D Kabsch fit behind it recovers a known rigid motion.
    pts = np.random.default_rng(0).normal(size=(20, 2))
    angle, shift = planar_rigid_fit(pts, rotate_z(np.c_[pts, np.zeros(20)], 0.3, about=pts.mean(0))[:, :2] + [1.0, -2.0])
    assert angle == pytest.approx(0.3) and np.allclose(shift, [1.0, -2.0])


def test_penetration_is_clamped_to_the_gel_thickness():
    depth = heightmap_from_triangles(sphere(3e-3), FACES)  # 1 mm further than the gel is thick
    assert depth.max() == pytest.approx(C.GEL_THICKNESS) and depth.min() >= 0.0
    flat_top = depth >= C.GEL_THICKNESS
    expected = np.pi * (2 * R * 1e-3 - 1e-6) / C.PIXEL_SIZE**2  # the cap deeper than 2 mm: a 1 mm press
    assert flat_top.sum() == pytest.approx(expected, rel=0.05)
    # The sensor still renders a valid frame.
    frame = TactileSensor("right").render_local(sphere(3e-3), FACES)
    assert frame.image.dtype == np.uint8 and np.isfinite(frame.marker_current).all()


def test_bad_input_is_rejected_with_a_clear_message():
    sensor = TactileSensor("left")
    tri = np.array([[0, 1, 2]])
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        sensor.render_local(np.zeros((4, 2)), tri)
    with pytest.raises(ValueError, match="NaN or inf"):
        sensor.render(np.full((3, 3), np.nan), tri, np.eye(4))
    with pytest.raises(ValueError, match="faces index"):
        sensor.render_local(np.zeros((3, 3)), np.array([[0, 1, 3]]))
    with pytest.raises(ValueError, match="integer"):
        sensor.render_local(np.zeros((3, 3)), tri.astype(float))
    with pytest.raises(ValueError, match="4x4"):
        sensor.render(np.zeros((3, 3)), tri, np.eye(3))
    with pytest.raises(ValueError, match="rotation"):
        sensor.render(np.zeros((3, 3)), tri, np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="side"):
        TactileSensor("middle")
    with pytest.raises(ValueError, match=r"\(240, 320\)"):
        render_image(np.zeros((10, 10)), load_optics())
    # An empty mesh is simply no contact.
    frame = sensor.render_local(np.zeros((0, 3)), np.zeros((0, 3), int))
    assert np.array_equal(frame.image, sensor.background_frame)
