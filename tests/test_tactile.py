"""GelSight Mini sensor: contact geometry, optics and markers against physical expectations."""

import numpy as np
import pytest
import trimesh

from mani_skill_softvt.tactile import TactileSensor, pad_frame
from mani_skill_softvt.tactile import constants as C
from mani_skill_softvt.tactile.geometry import contact_area, contact_centroid, penetration_map, to_pixels
from mani_skill_softvt.tactile.optics import load_calibration, render_image

R = 0.01  # sphere radius (m)
SPHERE = trimesh.creation.icosphere(subdivisions=4, radius=R)


def _sphere(depth, x=0.0, y=0.0):
    """Sphere vertices in the pad frame, pressed ``depth`` into the gel at (x, y)."""
    return np.asarray(SPHERE.vertices) + [x, y, R - depth], np.asarray(SPHERE.faces)


def test_sphere_press_gives_hertzian_contact_disc_centred_under_it():
    d, x, y = 0.5e-3, 1.2e-3, -0.7e-3
    frame = TactileSensor("left").render_local(*_sphere(d, x, y))
    radius = np.sqrt(contact_area(frame.depth) / np.pi)
    # Geometric intersection of a sphere with a plane: a disc of radius sqrt(2 R d - d^2) ~ sqrt(2 R d).
    # Tolerance: the icosphere's chords sit inside the sphere (sagitta ~ R/400) and the pixel
    # quantisation of the disc edge (~1 px of 0.059 mm on a 3 mm radius): 5 %.
    assert radius == pytest.approx(np.sqrt(2 * R * d - d * d), rel=0.05)
    centre = contact_centroid(frame.depth)
    np.testing.assert_allclose(centre, to_pixels(np.array([x, y])), atol=1.0)
    assert frame.depth.max() == pytest.approx(d, rel=0.02)


def test_no_contact_gives_exactly_the_background():
    sensor = TactileSensor("left")
    frame = sensor.render_local(*_sphere(-1e-3))  # 1 mm above the gel
    assert np.array_equal(frame.image, sensor.background_frame)
    assert np.array_equal(frame.marker_current, frame.marker_initial)
    assert np.array_equal(render_image(np.zeros((C.IMAGE_HEIGHT, C.IMAGE_WIDTH))), load_calibration().background)
    assert frame.image.shape == (240, 320, 3) and frame.image.dtype == np.uint8
    assert frame.marker_initial.shape == (C.MARKER_COLS * C.MARKER_ROWS, 2)


def test_pressing_deeper_never_shrinks_the_contact():
    areas = [contact_area(penetration_map(*_sphere(d))) for d in np.linspace(0.05e-3, 1.4e-3, 12)]
    assert all(b >= a for a, b in zip(areas, areas[1:]))
    assert areas[-1] > 5 * areas[0]


def test_penetration_is_clamped_to_the_gel():
    depth = penetration_map(*_sphere(3e-3))
    assert depth.max() == pytest.approx(C.MAX_PENETRATION) and C.MAX_PENETRATION < C.GEL_THICKNESS


def test_shear_moves_markers_under_the_contact_and_not_far_away():
    sensor = TactileSensor("left")
    x0 = -4e-3  # contact on the left half of the pad
    sensor.render_local(*_sphere(0.8e-3, x=x0))  # onset
    pressed = sensor.render_local(*_sphere(0.8e-3, x=x0))
    sheared = sensor.render_local(*_sphere(0.8e-3, x=x0 + 0.3e-3, y=0.2e-3))
    move = sheared.marker_current - pressed.marker_current
    pix = to_pixels(np.array([x0, 0.0]))
    dist = np.linalg.norm(pressed.marker_initial - pix, axis=1)
    near, far = dist < 30, dist > 150
    assert near.any() and far.any()
    # Under the contact the markers follow the patch: (+x, +y) = (+col, +row).
    expected = np.array([0.3e-3, 0.2e-3]) / C.PIXEL_SIZE
    mean_near = move[near].mean(axis=0)
    assert mean_near @ expected / np.linalg.norm(expected) > 0.5 * np.linalg.norm(expected)
    assert np.abs(move[far]).max() < 0.1


def test_twist_rotates_markers_about_the_contact():
    sensor = TactileSensor("left")
    verts, faces = _sphere(1.0e-3)
    sensor.render_local(verts, faces)
    base = sensor.render_local(verts, faces)
    theta = np.deg2rad(3.0)
    c, s = np.cos(theta), np.sin(theta)
    rot = verts @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])  # rotate about the pad normal by +theta
    twisted = sensor.render_local(rot, faces)
    centre = to_pixels(np.zeros(2))
    rel = base.marker_current - centre
    move = twisted.marker_current - base.marker_current
    near = np.linalg.norm(rel, axis=1) < 40
    # Counter-clockwise in (x, y): displacement along (-y, x) of the lever arm.
    tangential = (rel[near, 0] * move[near, 1] - rel[near, 1] * move[near, 0])
    assert (tangential > 0).sum() >= 0.8 * near.sum()


def test_left_and_right_fingers_are_mirrored():
    # A thin plate squeezed between two facing pads touches both at the same world point.
    left, right = TactileSensor("left"), TactileSensor("right")
    hand_x, hand_y, hand_z = np.eye(3)
    faces = np.asarray(SPHERE.faces)
    # World: left pad at -y looking +y, right pad at +y looking -y; the ball sits off-centre.
    offset = np.array([2e-3, 0.0, 1e-3])  # contact point off-centre along hand x and z
    pose_l = pad_frame(np.array([0, -(R - 0.6e-3), 0]) + [0, offset[1], 0], hand_y, hand_x)
    pose_r = pad_frame(np.array([0, (R - 0.6e-3), 0]) + [0, offset[1], 0], -hand_y, -hand_x)
    world = np.asarray(SPHERE.vertices) + offset
    fl = left.render(world, faces, pose_l)
    fr = right.render(world, faces, pose_r)
    cl, cr = contact_centroid(fl.depth), contact_centroid(fr.depth)
    assert cl is not None and cr is not None
    # Same row, mirrored column about the image centre.
    assert cl[1] == pytest.approx(cr[1], abs=0.5)
    assert cl[0] + cr[0] == pytest.approx(C.IMAGE_WIDTH - 1, abs=1.0)
    assert abs(cl[0] - (C.IMAGE_WIDTH - 1) / 2) > 10  # off-centre, so mirroring is visible


def test_bad_input_is_rejected():
    sensor = TactileSensor("left")
    with pytest.raises(ValueError, match="shape"):
        sensor.render_local(np.zeros((4, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="NaN"):
        sensor.render_local(np.full((3, 3), np.nan), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="side"):
        TactileSensor("middle")
