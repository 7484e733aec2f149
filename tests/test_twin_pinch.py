"""The twin-pinch study (campaign/softvt_campaign/studies/twin_pinch.py): its maths without a simulator, and
one grasp of the cube twin (slow)."""

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from softvt_campaign.studies.twin_pinch import (PAD_LENGTH, PAD_WIDTH, VIEW_HEIGHT, convex_gap, flat_face_patch,
                                                  nearest_face_tilt, run_grasp, turn_in_hand_deg, winkler_patch)
from mani_skill_softvt.tactile import constants as TC
from mani_skill_softvt.tactile.gel import foundation_stiffness
from mani_skill_softvt.tasks.constants import GRIPPER_FORCE_LIMIT

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


def test_convex_gap_of_a_tilted_box():
    # A 10 mm cube, bottom face 1 mm above the pad, turned 5 deg about pad y: over the bottom face
    # the gap is 1 mm + x tan(5 deg) (measured from the turned face's centre line); off the body, none.
    corners = np.array([[x, y, z] for x in (-5e-3, 5e-3) for y in (-5e-3, 5e-3) for z in (0.0, 10e-3)])
    r = Rotation.from_euler("y", -5.0, degrees=True).as_matrix()
    v = corners @ r.T + [0.0, 0.0, 1e-3]
    xy = np.array([[0.0, 0.0], [3e-3, 1e-3], [-2e-3, -4e-3], [20e-3, 0.0]])
    gap = convex_gap(xy, v)
    # The bottom face: points p with (p - c) . n = 0, n = r @ (0, 0, 1), c = (0, 0, 1 mm).
    n = r[:, 2]
    expected = 1e-3 - (n[0] * xy[:3, 0] + n[1] * xy[:3, 1]) / n[2]
    np.testing.assert_allclose(gap[:3], expected, rtol=0, atol=1e-12)
    assert np.isinf(gap[3])


@pytest.mark.parametrize("force", [1.0, 100.0])
def test_winkler_patch_of_a_hinged_flat_face_is_the_closed_form(force):
    # The same gel balance solved numerically on a sampled wedge (gap = x tan from one pad edge,
    # shifted: the balance cannot depend on where the face starts) and in closed form (GEL's pad
    # with 10 mm of its 20 mm length in view). Sampling error: about one cell along the patch edge.
    tilt, cell = np.arctan(0.01), 0.02e-3
    xs = np.arange(-GEL["width"] / 2 + cell / 2, GEL["width"] / 2, cell)
    ys = np.arange(-GEL["length"] / 2 + cell / 2, GEL["length"] / 2, cell)
    gx, gy = np.meshgrid(xs, ys)
    gap = (gx + GEL["width"] / 2) * np.tan(tilt) - 3e-5
    area, peak = winkler_patch(gap, np.abs(gy) <= GEL["view_height"] / 2, force, cell ** 2, GEL["stiffness"])
    want_area, want_peak = flat_face_patch(force, tilt, **GEL)
    assert area == pytest.approx(want_area, abs=GEL["view_height"] * cell)
    assert peak == pytest.approx(want_peak, abs=np.tan(tilt) * cell)


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
@pytest.mark.parametrize("yaw_mode", ["align", "0"])
def test_cube_twin_firm_grasp_shows_the_patch_of_its_hull(yaw_mode):
    """One firm grasp of the cube twin (closure 0.9, seed 0), the hand aligned to it (the face flat
    on the pad) or at its default heading (the cube held 3 deg crooked, friction-locked): the
    force limit binds, and each sensor's patch is the gel balance on the hull PhysX holds, solved
    apart on a finer grid (studies.twin_pinch.hull_patch)."""
    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id="rigid_stw_cube_hq")
    try:
        r = run_grasp(env, "rigid_stw_cube_hq", 0.9, 0, yaw_mode)
    finally:
        env.close()
    assert r["lifted"]
    grid_px = TC.PIXEL_SIZE * TC.GEL_GRID_DOWNSAMPLE  # the sensor's gel grid
    for side, pad in r["pads"].items():
        # Aligned, the face lies flat; at the default heading the cube keeps the yaw it settled with
        # (friction-locked in the pinch, docs/limitations.md), so its face is that far off the pad.
        expected_tilt = 0.0 if yaw_mode == "align" else abs(r["object_yaw_deg"])
        assert pad["tilt_deg"] == pytest.approx(expected_tilt, abs=1.0), side
        # The drive's limit binds here; the contact impulses of the last tick read it to within
        # a mN or so (10.0005 N measured), hence 1 %.
        assert 0.0 < pad["force_n"] <= 1.01 * GRIPPER_FORCE_LIMIT, side
        # Area: the grids differ by at most one sensor cell along the patch's edge, at most the
        # view's perimeter. Peak: the deepest cells sit up to a cell apart on a face sloping
        # tan(tilt), plus the hull face's own warp (0.2 mm over 17 mm: slope < 0.02).
        perimeter = 2e6 * (PAD_WIDTH + VIEW_HEIGHT) * grid_px  # mm^2
        assert pad["sensor_area_mm2"] == pytest.approx(pad["hull_area_mm2"], abs=perimeter), side
        slope = np.tan(np.radians(pad["tilt_deg"])) + 0.02
        assert pad["sensor_peak_um"] == pytest.approx(pad["hull_peak_um"], abs=1e6 * slope * grid_px), side
        # Model 2 showed the whole pad in view pressed (247 mm^2) at any force: the tet boundary
        # sat past the pad. The hull's patch is smaller: the crooked hold presses a strip.
        assert pad["sensor_area_mm2"] < (0.98 if yaw_mode == "align" else 0.5) * 1e6 * PAD_WIDTH * VIEW_HEIGHT, side
