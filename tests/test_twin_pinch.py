"""The twin-pinch study (mani_skill_softvt/studies/twin_pinch.py): its maths without a simulator, and
one grasp of the cube twin (slow)."""

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mani_skill_softvt.studies.twin_pinch import (PAD_LENGTH, PAD_WIDTH, VIEW_HEIGHT, flat_face_patch, nearest_face_tilt,
                                                  run_grasp, turn_in_hand_deg)
from mani_skill_softvt.tactile.gel import foundation_stiffness
from mani_skill_softvt.tactile.sensor import TactileSensor
from mani_skill_softvt.tasks.constants import GEL_PAD_HALF_EXTENTS, GRIPPER_FORCE_LIMIT

# Round numbers for the hand computations: K = 1e9 Pa/m, a 20 x 20 mm pad, 10 mm of it in view.
GEL = dict(stiffness=1e9, length=0.02, width=0.02, view_height=0.01)


def test_flat_face_hinged_strip_by_hand():
    # tan(tilt) = 0.01, F = 1 N: the strip regime (the pad is covered only from K L W^2 tan / 2 = 40 N).
    # d = sqrt(2 F tan / (K L)) = sqrt(0.02 / 2e7) = sqrt(1e-9) = 3.1623e-5 m;
    # w = d / tan = 3.1623e-3 m; area in view = w x 0.01 m = 3.1623e-5 m^2.
    area, peak = flat_face_patch(1.0, np.arctan(0.01), **GEL)
    assert peak == pytest.approx(3.1623e-5, rel=1e-4)
    assert area == pytest.approx(3.1623e-5, rel=1e-4)


def test_flat_face_covering_the_pad_by_hand():
    # F = 100 N > 40 N: d = F / (K L W) + tan W / 2 = 100 / 4e5 + 0.01 x 0.01 = 2.5e-4 + 1e-4 m;
    # the whole width is pressed, area in view = 0.02 x 0.01 m^2.
    area, peak = flat_face_patch(100.0, np.arctan(0.01), **GEL)
    assert peak == pytest.approx(3.5e-4, rel=1e-9)
    assert area == pytest.approx(2e-4, rel=1e-9)


@pytest.mark.parametrize("tilt", [0.0, 1e-9])
def test_flat_face_untilted_is_the_uniform_sink(tilt):
    force, k = 3.0, foundation_stiffness()
    area, peak = flat_face_patch(force, tilt)
    assert peak == pytest.approx(force / (k * PAD_LENGTH * PAD_WIDTH), rel=1e-6)
    assert area == pytest.approx(PAD_WIDTH * VIEW_HEIGHT)


@pytest.mark.parametrize("tilt_deg", [0.05, 1.0, 14.0])
def test_flat_face_is_continuous_where_the_strip_reaches_across_the_pad(tilt_deg):
    t = np.radians(tilt_deg)
    switch = GEL["stiffness"] * GEL["length"] * GEL["width"] ** 2 * np.tan(t) / 2
    below, above = flat_face_patch(switch * (1 - 1e-9), t, **GEL), flat_face_patch(switch * (1 + 1e-9), t, **GEL)
    assert below == pytest.approx(above, rel=1e-6)
    assert below[1] == pytest.approx(GEL["width"] * np.tan(t), rel=1e-6)  # d = W tan at the switch


def test_flat_face_without_force_shows_nothing():
    assert flat_face_patch(0.0, 0.1) == (0.0, 0.0)


def test_nearest_face_tilt():
    pad = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # pad +z along world -x
    assert pad @ pad.T == pytest.approx(np.eye(3)) and np.linalg.det(pad) == pytest.approx(1.0)
    flat = nearest_face_tilt(np.eye(3), pad)
    assert flat["face"] == "+x" and flat["tilt_deg"] == pytest.approx(0.0, abs=1e-6)
    turned = nearest_face_tilt(Rotation.from_euler("z", 3.0, degrees=True).as_matrix(), pad)
    assert turned["face"] == "+x" and turned["tilt_deg"] == pytest.approx(3.0)
    assert abs(turned["tilt_about_pad_x_deg"]) == pytest.approx(3.0)  # world z is the pad's y: a hinge along x
    assert turned["tilt_about_pad_y_deg"] == pytest.approx(0.0, abs=1e-9)


def test_turn_in_hand_ignores_what_the_hand_carries():
    def q(deg, axis="z"):
        x, y, z, w = Rotation.from_euler(axis, deg, degrees=True).as_quat()
        return np.array([w, x, y, z])

    assert turn_in_hand_deg([q(0), q(30)], [q(10), q(40)]) == pytest.approx(0.0, abs=1e-6)
    assert turn_in_hand_deg([q(0), q(30, "x")], [q(0), q(30, "x")]) == pytest.approx(0.0, abs=1e-6)
    assert turn_in_hand_deg([q(0), q(30)], [q(10), q(45)]) == pytest.approx(5.0)


@pytest.mark.slow
def test_cube_twin_aligned_firm_grasp():
    """One grasp (cube twin, hand aligned to it, closure 0.9, seed 0): the face lies flat on the pad
    and the gripper's force limit binds."""
    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id="rigid_stw_cube_hq")
    try:
        r = run_grasp(env, "rigid_stw_cube_hq", 0.9, 0, "align", TactileSensor("left", GEL_PAD_HALF_EXTENTS))
    finally:
        env.close()
    assert r["lifted"]
    for side, pad in r["pads"].items():
        assert pad["tilt_deg"] < 1.0, side
        # The drive's limit binds here; the contact impulses of the last tick read it to within
        # a mN or so (10.0005 N measured), hence 1 %.
        assert 0.0 < pad["force_n"] <= 1.01 * GRIPPER_FORCE_LIMIT, side
        # TODAY'S BEHAVIOUR, THE ARTEFACT (not a requirement): the sensor renders the twin's tet
        # boundary, which sits past the pad plane, so the patch covers the whole pad in view
        # (247 mm^2) whatever the contact. Flip this to a partial patch (like the cooked-hull
        # prototype's, 234 mm^2 and 100 um deep here) when the fix lands.
        assert pad["sensor_area_mm2"] >= 0.99e6 * PAD_WIDTH * VIEW_HEIGHT, side
