"""ManiSkill's and gymnasium's own tools on the SoftVT envs: vector envs in subprocesses with shared
memory, render_mode="sensors", every control mode, the axis-angle pose target, the sim backend and
the gripper encodings. All on the rigid suite (PhysX only)."""

import functools
import re

import gymnasium as gym
import numpy as np
import pytest
from mani_skill.utils.wrappers.gymnasium import CPUGymWrapper

import mani_skill_softvt  # noqa: F401  (registers the envs)
from mani_skill_softvt.physics.transforms import down_quat, down_rotvec, quat_angle
from mani_skill_softvt.tasks import constants as C
from mani_skill_softvt.contracts.actions import CONTROL_MODES, base_frame_pose, closure_to_q, gripper_action, normalized_gripper

ENV_ID, TASK = "SoftVTObjectRigid-v1", 3
OPEN_WIDTH, CLOSED_WIDTH = 2 * C.GRIPPER_Q_OPEN, 0.0  # jaw gap (m): 80 mm open; closed on nothing, the pads meet
TACTILE_H, TACTILE_W = 240, 320


def make_cpu_env(env_id: str, obs_mode: str, control_mode: str = "pd_joint_delta_pos") -> gym.Env:
    """Factory of a single gymnasium-conforming env (numpy, unbatched), importable by a spawned
    worker: it registers the SoftVT envs in that process too. Zero arm deltas hold a delta mode still."""
    import mani_skill_softvt  # noqa: F401

    return CPUGymWrapper(gym.make(env_id, task_id=TASK, obs_mode=obs_mode, control_mode=control_mode))


def _leaves(x, prefix=""):
    if isinstance(x, (dict, gym.spaces.Dict)):
        for k in x.keys():
            yield from _leaves(x[k], f"{prefix}/{k}")
    else:
        yield prefix, x


def _tcp_pose(u) -> np.ndarray:
    return u.agent.tcp.pose.raw_pose[0].cpu().numpy().astype(np.float64)  # world xyz, wxyz


def _hold_still(u, mode: str, closure: float = 0.0) -> np.ndarray:
    """The action that keeps the arm where it is in ``mode``, commanding the gripper ``closure``
    (0: open) in the mode's encoding."""
    arm = mode.removesuffix("_binary")
    if arm == "pd_ee_pose":
        a = base_frame_pose(_tcp_pose(u))  # absolute: the current pose as base-frame xyz and axis-angle
    elif arm == "pd_joint_pos":
        a = u.agent.robot.get_qpos()[0, :7].cpu().numpy()  # absolute: the current arm joints
    else:
        a = np.zeros(u.single_action_space.shape[0] - 1)  # deltas: no change
    return np.concatenate([a, [gripper_action(closure, mode)]]).astype(np.float32)


def _move(u, mode: str) -> np.ndarray:
    """An action that moves the TCP by centimetres within a few steps."""
    a = _hold_still(u, mode)
    arm = mode.removesuffix("_binary")
    if arm == "pd_ee_pose":
        a[2] += 0.05  # 5 cm up
    elif arm == "pd_joint_pos":
        a[0] += 0.2  # turn the base joint by 0.2 rad
    else:
        a[0] = 1.0  # a full normalised delta: +x for the TCP, or the base joint
    return a


# ---------------------------------------------------------------- vector envs
@pytest.mark.parametrize("obs_mode", [pytest.param("state", marks=pytest.mark.slow), pytest.param("rgb", marks=pytest.mark.slow),
                                      pytest.param("rgb+tactile", marks=pytest.mark.slow)])
def test_async_vector_env_with_shared_memory_in_spawned_workers(obs_mode):
    # Spawned workers start a fresh interpreter each (~20-30 s with the imports, the scene build and,
    # in rgb modes, the renderer's start-up), so only "state" runs by default.
    venv = gym.vector.AsyncVectorEnv([functools.partial(make_cpu_env, ENV_ID, obs_mode)] * 2, context="spawn")
    try:
        assert venv.num_envs == 2 and venv.single_action_space.shape == (8,)
        obs, _ = venv.reset(seed=[0, 1])
        spaces = dict(_leaves(venv.single_observation_space))
        leaves = dict(_leaves(obs))
        assert leaves.keys() == spaces.keys()
        for path, x in leaves.items():
            assert x.shape == (2, *spaces[path].shape) and x.dtype == spaces[path].dtype, path
            if x.dtype.kind == "f":
                assert np.isfinite(x).all(), path
        if obs_mode == "state":
            # Seeds 0 and 1 draw different joint noise and placements: the proprioception differs.
            assert not np.allclose(obs[0], obs[1])
        else:
            assert not np.allclose(obs["agent"]["qpos"][0], obs["agent"]["qpos"][1])
            # The object and the basket are placed differently: the third-person views differ.
            base = obs["sensor_data"]["base_camera"]["rgb"].astype(np.int16)
            assert np.abs(base[0] - base[1]).mean() > 1.0
        if obs_mode == "rgb+tactile":
            for side in ("left", "right"):
                t = obs["tactile"][side]
                # Nothing touches either gel: both envs show the sensor's reference frame, markers at rest.
                assert np.array_equal(t["rgb"][0], t["rgb"][1]) and not t["depth"].any()
                np.testing.assert_array_equal(t["marker_current"], t["marker_initial"])
        before = obs if obs_mode == "state" else obs["agent"]["qpos"]
        hold = np.zeros((2, 8), np.float32)
        hold[:, -1] = 1.0  # ManiSkill's "open": zero joint deltas, the gripper as it is
        obs, reward, terminated, truncated, info = venv.step(hold)
        assert reward.shape == terminated.shape == truncated.shape == (2,)
        assert not terminated.any() and not truncated.any() and not info["success"].any()
        for path, x in _leaves(obs):
            assert x.shape == (2, *spaces[path].shape), path
        after = obs if obs_mode == "state" else obs["agent"]["qpos"]
        assert np.abs(after - before).max() < 0.05  # zero deltas: joints and TCP barely move
    finally:
        venv.close()


# ---------------------------------------------------------------- render_mode="sensors"
# What each obs mode's sensor rendering holds (height, width) per image: ManiSkill renders colour and
# depth of each 224x224 camera in the non-visual modes, the obs mode's textures otherwise; "+tactile"
# adds both fingers' 320x240 GelSight frames.
CAMERA = (C.CAMERA_SIZE, C.CAMERA_SIZE)
SENSOR_IMAGES = {
    "state": [CAMERA] * 4,
    "state_dict": [CAMERA] * 4,
    "none": [CAMERA] * 4,
    "rgb": [CAMERA] * 2,
    "rgb+tactile": [(TACTILE_H, TACTILE_W)] * 2 + [CAMERA] * 2,
}


@pytest.fixture(scope="module")
def renderer():
    """An env kept alive for the module's render tests: SAPIEN releases its CPU renderer with the
    last env that holds it, and the next env's first picture pays the ~7 s start-up again."""
    env = gym.make(ENV_ID, task_id=TASK, obs_mode="none", render_mode="sensors")
    yield env
    env.close()


@pytest.mark.parametrize("obs_mode", list(SENSOR_IMAGES))
def test_render_mode_sensors_tiles_the_cameras_and_the_gelsights(obs_mode, renderer):
    env = CPUGymWrapper(gym.make(ENV_ID, task_id=TASK, obs_mode=obs_mode, render_mode="sensors"))
    obs, _ = env.reset(seed=0)
    img = env.render()
    sizes = SENSOR_IMAGES[obs_mode]
    # ManiSkill's tile_images (one row) sorts the images by height and stacks one under another only
    # if both fit the tallest and share its width: 224 + 224 exceeds both 224 and 240, so each image
    # is a column of its own.
    assert isinstance(img, np.ndarray) and img.dtype == np.uint8
    assert img.shape == (max(h for h, _ in sizes), sum(w for _, w in sizes), 3)
    x = 0
    for h, w in sizes:
        tile = img[:h, x:x + w]
        assert tile.std() > 1.0, (obs_mode, x)  # a rendered view, not an empty slot
        assert not img[h:, x:x + w].any()  # below a shorter image: the tiling's black padding
        x += w
    u = env.unwrapped
    if obs_mode == "rgb+tactile":
        # The tallest first: the two GelSight frames, at reset their reference images (nothing touches).
        for k, side in enumerate(("left", "right")):
            np.testing.assert_array_equal(img[:, k * TACTILE_W:(k + 1) * TACTILE_W], u.tactile_background(side))
    if obs_mode.startswith("rgb"):
        # The cameras' columns are what the policy observes.
        x0 = 2 * TACTILE_W if obs_mode == "rgb+tactile" else 0
        for k, cam in enumerate(("base_camera", "hand_camera")):
            col = img[:C.CAMERA_SIZE, x0 + k * C.CAMERA_SIZE:x0 + (k + 1) * C.CAMERA_SIZE]
            np.testing.assert_array_equal(col, obs["sensor_data"][cam]["rgb"])
    if obs_mode == "none":
        assert obs == {}  # rendering the sensors does not make "none" observe anything
    env.close()


# ---------------------------------------------------------------- control modes
@pytest.mark.parametrize("mode", CONTROL_MODES)
def test_every_control_mode_holds_still_and_moves(mode):
    env = gym.make(ENV_ID, task_id=TASK, obs_mode="none", control_mode=mode)
    u = env.unwrapped
    assert u.control_mode == mode
    space = env.action_space
    assert space.shape == ((8,) if "joint" in mode else (7,))
    # The gripper: the paper's closure in pd_ee_pose, ManiSkill's normalised action in its own modes, where
    # the whole action is in [-1, 1] in the delta modes (what ManiSkill's diffusion-policy baseline asserts).
    assert (space.low[-1], space.high[-1]) == ((-1.0, 1.0) if normalized_gripper(mode) else (0.0, 1.0))
    if "delta" in mode:
        assert (space.low == -1).all() and (space.high == 1).all()
    env.reset(seed=0)
    start = _tcp_pose(u)[:3]
    for _ in range(5):
        env.step(_hold_still(u, mode))
    assert np.linalg.norm(_tcp_pose(u)[:3] - start) < 5e-3
    # The same mode reads a real command as motion: the hold above was not a no-op by accident.
    for _ in range(5):
        env.step(_move(u, mode))
    assert np.linalg.norm(_tcp_pose(u)[:3] - start) > 1e-2
    env.close()


@pytest.mark.parametrize("mode", ["pd_ee_pose", "pd_ee_pose_binary"])
def test_pd_ee_pose_reads_the_orientation_as_an_axis_angle(mode):
    env = gym.make(ENV_ID, task_id=TASK, obs_mode="none", control_mode=mode)
    u = env.unwrapped
    env.reset(seed=0)
    start = _tcp_pose(u)
    yaw = 0.4
    assert np.degrees(quat_angle(start[3:], down_quat(yaw))) > 15  # the hand starts about 23 deg away
    action = np.concatenate([base_frame_pose(start)[:3], down_rotvec(yaw), [0.0]]).astype(np.float32)
    for _ in range(40):
        env.step(action)
    end = _tcp_pose(u)
    # The top-down hand turned by the yaw, where it was. (Read as XYZ Euler angles, the same three
    # numbers would tilt the hand by tens of degrees.)
    assert np.degrees(quat_angle(end[3:], down_quat(yaw))) < 1.0
    assert np.linalg.norm(end[:3] - start[:3]) < 5e-3
    env.close()


# ---------------------------------------------------------------- backend
def test_sim_backend_auto_is_the_cpu_and_a_gpu_backend_is_refused():
    env = gym.make(ENV_ID, task_id=TASK, obs_mode="none", sim_backend="auto")
    u = env.unwrapped
    assert u.backend.sim_backend == "physx_cpu" and not u.gpu_sim_enabled and str(u.device) == "cpu"
    env.close()
    for backend in ("physx_cuda", "gpu"):
        with pytest.raises(ValueError, match=re.escape(f"'{backend}'")):
            gym.make(ENV_ID, task_id=TASK, obs_mode="none", sim_backend=backend)


# ---------------------------------------------------------------- gripper encodings
@pytest.mark.parametrize("mode", CONTROL_MODES)
def test_gripper_value_in_binary_and_continuous_modes(mode):
    env = gym.make(ENV_ID, task_id=TASK, obs_mode="none", control_mode=mode)
    u = env.unwrapped

    def width_after(value, steps=30):
        env.reset(seed=0)
        assert u.gripper_width == pytest.approx(OPEN_WIDTH, abs=1e-4)
        action = _hold_still(u, mode)
        action[-1] = value  # the raw gripper action of the mode
        for _ in range(steps):
            env.step(action)  # in the air: nothing between the pads
        return u.gripper_width

    if mode.endswith("_binary"):
        # pd_ee_pose: < 0.5 open, >= 0.5 close; ManiSkill's modes: its +1 open, -1 close (sign).
        opens, closes = (0.4, -0.4) if normalized_gripper(mode) else (0.3, 0.7)
        assert width_after(opens) == pytest.approx(OPEN_WIDTH, abs=1e-3)
        assert width_after(closes) == pytest.approx(CLOSED_WIDTH, abs=1e-3)
    else:
        # A closure of 0.3 (ManiSkill's modes: 1 - 2 * 0.3 = 0.4) drives the jaw to its target
        # 2 * q(0.3) = 50 mm: partway.
        w = width_after(gripper_action(0.3, mode))
        assert CLOSED_WIDTH + 0.01 < w < OPEN_WIDTH - 0.01
        assert w == pytest.approx(2 * closure_to_q(0.3), abs=1e-3)
        if normalized_gripper(mode):
            assert width_after(1.0) == pytest.approx(OPEN_WIDTH, abs=1e-3)  # ManiSkill's +1: open
            assert width_after(-1.0) == pytest.approx(CLOSED_WIDTH, abs=1e-3)  # -1: closed
    env.close()


@pytest.mark.parametrize("mode", ["pd_joint_delta_pos", "pd_ee_delta_pose"])
def test_the_gripper_action_drives_the_fingers_as_maniskills_panda_does(mode):
    # ManiSkill's own Panda (PickCube-v1) and SoftVT's, the same normalised gripper action: the same
    # finger drive targets (SoftVT's Panda has ManiSkill's finger range; only its force limit differs).
    targets = {}
    for env_id, kwargs in (("PickCube-v1", {}), (ENV_ID, {"task_id": TASK})):
        env = gym.make(env_id, obs_mode="none", control_mode=mode, **kwargs)
        env.reset(seed=0)
        assert (env.action_space.low[-1], env.action_space.high[-1]) == (-1.0, 1.0)
        for a in (1.0, 0.4, -0.3, -1.0):
            action = np.zeros(env.action_space.shape, np.float32)
            action[-1] = a
            env.step(action)
            targets.setdefault(env_id, []).append(env.unwrapped.agent.robot.get_drive_targets()[0, -2:].numpy())
        env.close()
    np.testing.assert_allclose(targets[ENV_ID], targets["PickCube-v1"], atol=1e-7)
