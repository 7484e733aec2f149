"""The GelSight's settings are one frozen config that the sensor reads in full (tactile/config.py).

Each check is the physics a setting stands for: the foundation k = (1 - nu) E / ((1 + nu)(1 - 2 nu) h)
under a flat face (sink F / (k A)), the gel's travel (its thickness), the dots' drawn area (pi r^2)
and the flow's 1 / h scaling (a volume V pressed in moves the surface V / (2 pi h r))."""

import numpy as np
import pytest
import trimesh

from mani_skill_softvt.tactile import TactileConfig, TactileSensor
from mani_skill_softvt.tactile import constants as C
from mani_skill_softvt.tactile.config import DEFAULT_TACTILE
from mani_skill_softvt.tactile.gel import foundation_stiffness

BOX = trimesh.creation.box(extents=(8e-3, 6e-3, 4e-3))


def resting(mesh, depth: float = 0.0) -> np.ndarray:
    """Vertices moved so the lowest face lies ``depth`` past the gel plane (pad frame z = 0)."""
    v = np.asarray(mesh.vertices, np.float64)
    return v - [0.0, 0.0, v[:, 2].min() + depth]


def test_the_defaults_are_the_constants_and_a_bad_setting_is_named():
    assert DEFAULT_TACTILE == TactileConfig(C.GEL_MODULUS, C.GEL_POISSON, C.GEL_THICKNESS, C.GEL_GRID_DOWNSAMPLE,
                                            C.MARKER_RADIUS, C.SHEAR_DECAY, C.FLOW_POOL, C.FLOW_SURFACE_FACTOR)
    stiffer = DEFAULT_TACTILE.with_overrides({"gel_modulus": 1.2e6}, gel_thickness=1e-3)
    assert (stiffer.gel_modulus, stiffer.gel_thickness, stiffer.gel_poisson) == (1.2e6, 1e-3, C.GEL_POISSON)
    assert DEFAULT_TACTILE.gel_modulus == C.GEL_MODULUS and stiffer.signature()["gel_thickness"] == 1e-3
    with pytest.raises(ValueError, match=r"tactile settings \['gel_stiffness'\] are not settings"):
        DEFAULT_TACTILE.with_overrides(gel_stiffness=1.0)
    for bad, match in (({"gel_poisson": 0.5}, "gel_poisson=0.5"), ({"gel_thickness": -1e-3}, "gel_thickness"),
                       ({"grid_downsample": 7}, "grid_downsample=7 must divide"),
                       ({"flow_pool": 2.5}, "flow_pool=2.5 must be a whole number")):
        with pytest.raises(ValueError, match=match):
            DEFAULT_TACTILE.with_overrides(bad)
    with pytest.raises(Exception):  # frozen: nothing patches a config in place
        DEFAULT_TACTILE.gel_modulus = 1.0


def test_a_flat_face_sinks_a_stiffer_thinner_gel_by_f_over_k_a():
    """Four times the modulus on half the thickness is 8x the foundation stiffness: the same flat face
    under the same force sinks the gel an eighth as deep, each by F / (k A)."""
    force, area = 3.0, 8e-3 * 6e-3
    thin = DEFAULT_TACTILE.with_overrides(gel_modulus=4 * C.GEL_MODULUS, gel_thickness=C.GEL_THICKNESS / 2)
    sinks = {}
    for name, config in (("default", DEFAULT_TACTILE), ("thin", thin)):
        sensor = TactileSensor("left", config=config)
        k = foundation_stiffness(config.gel_modulus, config.gel_thickness, config.gel_poisson)
        assert sensor.stiffness == pytest.approx(k)
        ind, sinks[name] = sensor.indentation(resting(BOX), BOX.faces, force, deformable=False)
        assert sinks[name] == pytest.approx(force / (k * area), rel=0.03)  # +-1 grid px of area per side
        assert k * ind.sum() * sensor.grid_pixel ** 2 == pytest.approx(force, rel=1e-9)  # it carries F
    assert sinks["thin"] / sinks["default"] == pytest.approx(1 / 8, rel=1e-9)  # the same pixels, k x 8


def test_the_gel_travel_is_its_thickness():
    """A face pushed 3 mm past the plane (prescribed geometry) bottoms out on the acrylic: the
    indentation is clipped at the gel's thickness, 2 mm by default, 1 mm for a 1 mm gel."""
    for h in (C.GEL_THICKNESS, 1e-3):
        ind, _ = TactileSensor("left", config=DEFAULT_TACTILE.with_overrides(gel_thickness=h)).indentation(
            resting(BOX, 3e-3), BOX.faces)
        assert ind.max() == pytest.approx(h)


def test_marker_radius_sets_the_dots_drawn_area():
    """Each dot darkens the background frame over pi (r + 1/2)^2 pixels: OpenCV fills the disc of
    radius r and draws its rim as a 1 px anti-aliased line centred on r (within 10 %)."""
    covered = {}
    for r in (3.0, 6.0):
        sensor = TactileSensor("left", config=DEFAULT_TACTILE.with_overrides(marker_radius=r))
        background = sensor.optics.background.astype(float)
        contrast = background - np.array(C.MARKER_COLOR, float)
        # Coverage of each pixel: how far it went from the gel's colour to the dot's.
        coverage = (background - sensor.background_frame) / np.where(np.abs(contrast) > 20, contrast, np.inf)
        covered[r] = coverage.mean(axis=2).sum() / (C.MARKER_COLS * C.MARKER_ROWS)
        assert covered[r] == pytest.approx(np.pi * (r + 0.5) ** 2, rel=0.1)
    assert covered[6.0] > 3 * covered[3.0]


def test_flow_scales_as_one_over_the_gel_thickness():
    """The same indentation map (prescribed geometry within both gels' travel) moves the markers by
    V / (2 pi h r): twice as far on a gel half as thick."""
    moved = {}
    for h in (C.GEL_THICKNESS, C.GEL_THICKNESS / 2):
        sensor = TactileSensor("left", config=DEFAULT_TACTILE.with_overrides(gel_thickness=h))
        frame = sensor.render_local(resting(trimesh.creation.icosphere(subdivisions=4, radius=0.01), 2e-4),
                                    trimesh.creation.icosphere(subdivisions=4, radius=0.01).faces)
        moved[h] = np.linalg.norm(frame.marker_current - frame.marker_initial, axis=1)
    assert moved[C.GEL_THICKNESS].max() > 0.05  # px: the markers did move
    assert moved[C.GEL_THICKNESS / 2] == pytest.approx(2 * moved[C.GEL_THICKNESS], rel=1e-4, abs=1e-4)
