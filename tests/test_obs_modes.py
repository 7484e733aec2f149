"""Every ManiSkill obs mode, with touch: what the cameras give is the scene as drawn, squeeze included.

The soft object is drawn each step from its FEM nodes (its visual meshes carried by the tets they
lie in). Its depth and its points must lie on that drawn surface within what ManiSkill's formats
resolve: depth is int16 millimetres along the optical axis (truncated: a pixel's depth is short of
the true one by less than 1 mm, so the back-projected point lies on the pixel's ray less than
1 mm / cos(theta) from the surface, theta the ray's angle to the axis); a point cloud is built from
SAPIEN's position texture, int16 millimetres in each camera-frame coordinate (less than sqrt(3) mm
from the surface). The squeeze moves the surface by more than those bounds, so the test also tells
the squeezed shape from the rest shape.
"""

import re

import gymnasium as gym
import numpy as np
import pytest
import trimesh

import mani_skill_softvt  # noqa: F401  (registers the envs)
from mani_skill_softvt.calibration import protocol as P
from mani_skill_softvt.expert.grasp_script import GraspPlan, run_grasp_script
from mani_skill_softvt.contracts.observations import NATIVE_CAMERA_SIZE, OBS_MODES, TEXTURES, CameraSize, ObsMode
from mani_skill_softvt.physics.transforms import yaw_between

DEPTH_QUANTUM = 1e-3  # m: ManiSkill's depth and SAPIEN's position texture are int16 millimetres
FLOAT_SLACK = 1e-5  # m: float32 rounding of vertices and camera poses at < 1 m, with a wide margin


def distances_to(surface, points) -> np.ndarray:
    """Exact distance of each point to a triangle mesh (trimesh's brute-force closest point)."""
    v, f = surface
    _, d, _ = trimesh.proximity.closest_point_naive(trimesh.Trimesh(v, f, process=False), points)
    return d


def object_id(env, name="object") -> int:
    ids = [k for k, actor in env.unwrapped.segmentation_id_map.items() if actor.name == name]
    assert len(ids) == 1, f"{name}: {ids}"
    return ids[0]


def back_project(depth_mm, pixels, intrinsic_cv, extrinsic_cv):
    """World points of ``pixels`` (rows, cols) at their depth, and each ray's cos(theta) to the axis."""
    rows, cols = pixels
    z = depth_mm[rows, cols].astype(np.float64) / 1000.0
    k = intrinsic_cv.astype(np.float64)
    # OpenCV intrinsics: pixel (col, row) covers [col, col + 1); its centre is where the ray goes.
    cam = np.c_[(cols + 0.5 - k[0, 2]) * z / k[0, 0], (rows + 0.5 - k[1, 2]) * z / k[1, 1], z]
    rot, t = extrinsic_cv[:, :3].astype(np.float64), extrinsic_cv[:, 3].astype(np.float64)
    return (cam - t) @ rot, z / np.linalg.norm(cam, axis=1)


def test_every_spelling_of_a_camera_size_is_one_camera_size():
    """None, "native", "HxW", a (height, width) pair from a record: one type, one meaning."""
    assert CameraSize.of(None) == CameraSize.of("native") == CameraSize.of([224, 224]) == NATIVE_CAMERA_SIZE
    assert NATIVE_CAMERA_SIZE.native and NATIVE_CAMERA_SIZE.sensor_configs() == {}
    small = CameraSize.of("84x96", "--camera-size")
    assert small == (84, 96) == CameraSize.of((84, 96)) and (small.height, small.width, small.name) == (84, 96, "84x96")
    assert not small.native and small.sensor_configs() == {"width": 96, "height": 84}
    for bad, message in (("84", "--camera-size '84': give HxW"), ("4x4", "--camera-size 4x4: give (height, width), "
                                                                         "each at least 8 pixels")):
        with pytest.raises(ValueError, match=re.escape(message)):
            CameraSize.of(bad, "--camera-size")


def test_named_obs_modes_render_maniskills_textures():
    """Each named mode renders the textures ManiSkill's parser gives it; touch only with cameras."""
    from mani_skill.envs.utils.observations import ALL_VISUAL_TEXTURES, parse_obs_mode_to_struct

    assert set(TEXTURES) == set(ALL_VISUAL_TEXTURES)
    for name in OBS_MODES:
        mode = ObsMode.parse(name)
        if mode.camera == "none":
            continue
        visual = parse_obs_mode_to_struct(mode.camera).visual
        assert mode.textures == {t for t in TEXTURES if getattr(visual, t)}, name
    assert ObsMode.parse("rgb+depth+state+tactile").textures == {"rgb", "depth"}
    assert ObsMode.parse("normal").shader_pack == "default" and ObsMode.parse("rgbd").shader_pack == "minimal"
    for bad in ("state+tactile", "none+tactile", "rgbd+depht", "tactile"):
        with pytest.raises(ValueError, match=bad.replace("+", r"\+")):
            ObsMode.parse(bad)


@pytest.fixture(scope="module")
def squeezed():
    """Object-Soft task 3 (the soft cube) closed on at full closure and stopped there, on the table:
    the observation in depth+segmentation, the drawn surface before the fingers touched and now,
    and the env state."""
    env = gym.make("SoftVTObjectSoft-Task3-v1", obs_mode="depth+segmentation")
    env.reset(seed=3)
    u = env.unwrapped
    rest = u.drawn_surface("object")
    yaw = yaw_between(u.rest_vertices("object"), u.settled_nodes("object"))

    def stop_when_closed(phase, i, n):
        return "stop" if phase == "close" and i == n - 1 else None

    run_grasp_script(env, GraspPlan(closure=1.0, yaw=float(yaw), steps=dict(P.STEPS)), on_step=stop_when_closed)
    out = dict(obs=u.get_obs(unflattened=True), rest=rest, surface=u.drawn_surface("object"),
               deformation=u.deformation("object"), state=u.get_state_dict(), id=object_id(env))
    env.close()
    return out


@pytest.mark.parametrize("camera", ["base_camera", "hand_camera"])
def test_depth_of_the_squeezed_soft_object_lies_on_its_drawn_fem_surface(squeezed, camera):
    assert squeezed["deformation"] > 3 * DEPTH_QUANTUM  # squeezed by more than the depth resolves
    images, params = squeezed["obs"]["sensor_data"][camera], squeezed["obs"]["sensor_param"][camera]
    depth, seg = images["depth"][0, ..., 0].numpy(), images["segmentation"][0, ..., 0].numpy()
    assert str(images["depth"].dtype) == "torch.int16" and str(images["segmentation"].dtype) == "torch.int16"
    pixels = np.nonzero(seg == squeezed["id"])
    assert len(pixels[0]) > 50, f"{camera} sees {len(pixels[0])} pixels of the object"
    points, cos = back_project(depth, pixels, params["intrinsic_cv"][0].numpy(), params["extrinsic_cv"][0].numpy())
    # On the squeezed surface within the depth's truncation along each ray...
    along_axis = distances_to(squeezed["surface"], points) * cos
    assert along_axis.max() < DEPTH_QUANTUM + FLOAT_SLACK, along_axis.max()
    # ...and not on the rest shape: somewhere the squeeze moved the seen surface beyond that bound.
    from_rest = distances_to(squeezed["rest"], points) * cos
    assert from_rest.max() > 2 * DEPTH_QUANTUM, from_rest.max()


# The depth test above keeps the squeezed surface.
@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_point_cloud_of_the_object_lies_on_its_drawn_surface_with_touch_beside_it(squeezed):
    env = gym.make("SoftVTObjectSoft-Task3-v1", obs_mode="pointcloud+tactile")
    env.reset(seed=3)
    env.unwrapped.set_state_dict(squeezed["state"])
    obs = env.unwrapped.get_obs(unflattened=True)
    cloud = obs["pointcloud"]
    xyzw, seg = cloud["xyzw"][0].numpy(), cloud["segmentation"][0, :, 0].numpy()
    assert "sensor_data" not in obs or not obs["sensor_data"]  # the cameras' images became the cloud
    assert cloud["rgb"].shape[:2] == cloud["xyzw"].shape[:2] == cloud["segmentation"].shape[:2]
    np.testing.assert_array_equal(xyzw[:, 3], (seg != 0).astype(np.float32))  # w: a surface was hit
    points = xyzw[seg == object_id(env)][:, :3].astype(np.float64)
    assert len(points) > 50
    dist = distances_to(env.unwrapped.drawn_surface("object"), points)
    assert dist.max() < np.sqrt(3) * DEPTH_QUANTUM + FLOAT_SLACK, dist.max()
    for side in ("left", "right"):  # both GelSights, pressed by the squeeze
        assert obs["tactile"][side]["depth"].numpy().max() > 0, side
    env.close()


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_spatial_instances_have_two_stable_ids_named_as_the_rigid_twins():
    env = gym.make("SoftVTSpatialSoft-v1", task_id=0, obs_mode="segmentation")
    obs, _ = env.reset(seed=0)
    u = env.unwrapped
    ids = {name: object_id(env, name) for name in ("left", "right")}
    assert ids["left"] != ids["right"]
    for _ in range(2):
        seen = set(np.unique(obs["sensor_data"]["base_camera"]["segmentation"].numpy()))
        assert set(ids.values()) <= seen  # both instances in the third-person view, each with its id
        assert {name: object_id(env, name) for name in ids} == ids  # stable across steps
        obs, *_ = env.step(_hold(u))
    env.close()
    twin = gym.make("SoftVTSpatialRigid-v1", task_id=0, obs_mode="segmentation")
    twin.reset(seed=0)
    assert {a.name for a in twin.unwrapped.segmentation_id_map.values()} >= {"left", "right"}
    twin.close()


def _hold(u):
    from mani_skill_softvt.contracts.actions import ee_action

    return ee_action(u.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64), 0.0)
