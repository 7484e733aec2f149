"""The four SoftVTBench suites as ManiSkill envs: registration, predicates, seeds, OOD, no leaks."""

import cv2
import gymnasium as gym
import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

import mani_skill_softvt  # noqa: F401  (registers the envs)
from mani_skill_softvt.contracts.actions import ee_action
from mani_skill_softvt.tasks import constants as C
from mani_skill_softvt.tasks.suites import NUM_TASKS, OOD_CONDITIONS, SUITES, list_tasks
from mani_skill_softvt.tactile.constants import GEL_THICKNESS

ENV_IDS = [s.env_id for s in SUITES.values()]


def _hold_still(env, closure=0.0):
    """An action that keeps the TCP where it is."""
    tcp = env.unwrapped.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64)
    return ee_action(tcp, closure)


def _step_info(env, n=1):
    for _ in range(n):
        _, _, terminated, truncated, info = env.step(_hold_still(env))
    return {k: bool(v[0]) if isinstance(v, torch.Tensor) and v.numel() == 1 and v.dtype == torch.bool else v
            for k, v in info.items()}, bool(terminated[0])


# Ten env builds and settles per suite, about a minute each: every suite runs with ``-m slow`` (CI
# runs it). The default run checks that task 4's asset settles in every suite (the
# privacy test below) and the grasp env's soft cube (``test_grasp_env``'s rest test).
@pytest.mark.slow
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_task_makes_resets_and_steps(env_id):
    suite = next(s.name for s in SUITES.values() if s.env_id == env_id)
    for task_id in range(NUM_TASKS):
        env = gym.make(env_id, task_id=task_id, obs_mode="state")
        obs, info = env.reset(seed=task_id)
        assert env.unwrapped.settle_info["settled"]
        assert env.unwrapped.instruction == list_tasks(suite)[task_id].instruction
        obs, rew, term, trunc, info = env.step(_hold_still(env))
        assert obs.shape == env.observation_space.shape and torch.isfinite(obs).all()
        assert not bool(info["success"][0]) and not bool(info["dropped"][0])
        env.close()


def test_task_list_and_registration_errors():
    assert len(list_tasks("spatial_rigid")) == NUM_TASKS
    with pytest.raises(ValueError, match="task_id"):
        gym.make("SoftVTObjectSoft-v1", task_id=10)
    with pytest.raises(ValueError, match="obs_mode 'pointcloud\\+depht'"):
        gym.make("SoftVTObjectSoft-v1", task_id=0, obs_mode="pointcloud+depht")
    with pytest.raises(ValueError, match="touch comes with camera images"):
        gym.make("SoftVTObjectSoft-v1", task_id=0, obs_mode="state+tactile")


@pytest.fixture(scope="module")
def object_env():
    env = gym.make("SoftVTObjectSoft-v1", task_id=3, obs_mode="state")
    yield env
    env.close()


@pytest.fixture(scope="module")
def spatial_env():
    env = gym.make("SoftVTSpatialRigid-v1", task_id=1, obs_mode="state")  # "right" instance
    yield env
    env.close()


def _target_pose(env, dz=0.0):
    u = env.unwrapped
    lo, hi = (np.asarray(v) for v in u.target_region)
    p = u.target.pose.p[0].cpu().numpy().astype(np.float64)
    return np.array([p[0] + 0.5 * (lo[0] + hi[0]), p[1] + 0.5 * (lo[1] + hi[1]), p[2] + lo[2] + dz, 1, 0, 0, 0])


def test_object_at_rest_in_basket_succeeds_and_outside_does_not(object_env):
    env, u = object_env, object_env.unwrapped
    env.reset(seed=1)
    info, _ = _step_info(env, 3)
    assert not info["success"] and not info["in_target"]
    u.place_object("object", _target_pose(env), settle_time=0.5)
    info, terminated = _step_info(env, 2)
    assert info["in_target"] and info["success"] and terminated
    # Beside the basket, on the table, at rest: not a success.
    env.reset(seed=1)
    beside = _target_pose(env)
    beside[1] += 0.15
    beside[2] = 0.0
    u.place_object("object", beside, settle_time=0.5)
    info, _ = _step_info(env, 2)
    assert not info["success"] and not info["in_target"] and not info["dropped"]


def test_spatial_success_checks_the_instance(spatial_env):
    env, u = spatial_env, spatial_env.unwrapped
    assert u.target_instance == "right"
    env.reset(seed=2)
    u.place_object("left", _target_pose(env), settle_time=0.5)
    info, _ = _step_info(env, 2)
    assert info["other_in_target"] and not info["in_target"] and not info["success"]
    env.reset(seed=2)
    u.place_object("right", _target_pose(env), settle_time=0.5)
    info, _ = _step_info(env, 2)
    assert info["in_target"] and info["success"]


def test_a_drop_is_detected_and_ends_the_episode(object_env):
    env, u = object_env, object_env.unwrapped
    env.reset(seed=3)
    centroid = u.soft_nodes("object").mean(axis=0)
    # Released 10 cm above the table, away from the basket: free fall reaches 0.25 m/s after 3 mm.
    u.place_object("object", np.array([centroid[0], centroid[1], 0.10, 1, 0, 0, 0]))
    for _ in range(6):
        info, terminated = _step_info(env)
        if info["dropped"]:
            break
    assert info["dropped"] and info["fail"] and terminated and not info["success"]


def test_same_seed_same_initial_state_and_different_seed_differs(object_env):
    env = object_env
    env.reset(seed=11)
    a = env.unwrapped.get_state().clone()
    env.reset(seed=11)
    b = env.unwrapped.get_state().clone()
    env.reset(seed=12)
    c = env.unwrapped.get_state().clone()
    assert torch.equal(a, b)
    assert not torch.allclose(a, c)


# One condition per factor (light, mass, stiffness) by default, each through its own code path; the
# other six differ only in the value, so they run with ``-m slow`` (CI runs them).
_ONE_PER_FACTOR = {"light_180", "mass_x2.5", "youngs_modulus_x0.5"}


@pytest.mark.parametrize("condition", [c if c in _ONE_PER_FACTOR else pytest.param(c, marks=pytest.mark.slow)
                                       for c in sorted(OOD_CONDITIONS)])
def test_ood_options_change_exactly_their_factor(object_env, condition):
    env, u = object_env, object_env.unwrapped
    env.reset(seed=7)
    nominal = _factors(u)
    layout = _layout(u)
    env.reset(seed=7, options={"ood": condition})
    shifted = _factors(u)
    key, value = OOD_CONDITIONS[condition]
    expected = dict(nominal)
    expected[key] = value if key == "light_intensity" else nominal[key] * value
    for k in nominal:
        assert shifted[k] == pytest.approx(expected[k], rel=1e-5), k
    # Same initial state as the ID episode: robot, target and object placement.
    shifted_layout = _layout(u)
    np.testing.assert_array_equal(layout["qpos"], shifted_layout["qpos"])
    np.testing.assert_array_equal(layout["target"], shifted_layout["target"])
    # The object settles under its own (possibly heavier or softer) weight: sub-millimetre.
    np.testing.assert_allclose(layout["object_xy"], shifted_layout["object_xy"], atol=1e-3)


def test_a_reset_to_given_states_takes_its_factors_in_the_rebuilt_scene(object_env):
    """ManiSkill's reset to env states skips _initialize_episode; the scene it rebuilds takes the
    reset's factors (materials and light are not part of the state), and nominal ones without."""
    env, u = object_env, object_env.unwrapped
    env.reset(seed=7)
    nominal, state = _factors(u), u.get_state_dict()
    env.reset(options={"ood": "youngs_modulus_x2.0", "reset_to_env_states": {"env_states": state}})
    assert _factors(u)["youngs_modulus_scale"] == pytest.approx(2.0 * nominal["youngs_modulus_scale"], rel=1e-5)
    assert u.factors.youngs_modulus_scale == 2.0
    env.reset(options={"reset_to_env_states": {"env_states": state}})
    assert _factors(u) == pytest.approx(nominal, rel=1e-6) and u.factors.youngs_modulus_scale == 1.0


def _factors(u):
    ev = u.evaluator_state()["object"]
    return {"light_intensity": u.live_light_intensity(), "mass_scale": ev["mass"], "youngs_modulus_scale": ev["youngs_modulus"]}


def _layout(u):
    return {"qpos": u.agent.robot.get_qpos()[0].cpu().numpy().copy(),
            "target": u.target.pose.raw_pose[0].cpu().numpy().copy(),
            "object_xy": u.soft_nodes("object").mean(axis=0)[:2].copy()}


def test_bad_reset_options_are_rejected(object_env):
    with pytest.raises(ValueError, match="unknown OOD condition"):
        object_env.reset(seed=0, options={"ood": "gravity_x2"})
    with pytest.raises(ValueError, match="positive finite"):
        object_env.reset(seed=0, options={"mass_scale": -1.0})
    with pytest.raises(ValueError, match="youngs_modulus_sacle"):  # a misspelled factor is not silently nominal
        object_env.reset(seed=0, options={"youngs_modulus_sacle": 0.5})


# --------------------------------------------------------------------------- no leaks
EVALUATOR_KEYWORDS = ("node", "x0", "deform", "young", "mass", "material", "centroid", "object_pose", "soft")


def _leaves(obs, prefix=""):
    if isinstance(obs, dict):
        for k, v in obs.items():
            yield from _leaves(v, f"{prefix}/{k}")
    else:
        yield prefix, obs


# Every kind of obs mode in every suite: the state modes, images, the depth, segmentation, position and
# normal textures, point clouds and raw sensor data, with touch. Spatial-Soft's two-instance scene runs
# its richest image mode by default; each camera mode beyond rgb runs once by default (in the suite
# named), the rest (about 20 s each) with ``-m slow``: the modes share their code across suites.
LEAK_MODES = {"state": None, "state_dict": None, "rgb": None, "rgb+tactile": "SoftVTSpatialSoft-v1",
              "pointcloud+tactile": "SoftVTObjectSoft-v1", "sensor_data+tactile": "SoftVTObjectRigid-v1",
              "rgb+depth+segmentation+normal+state+tactile": "SoftVTSpatialRigid-v1"}


@pytest.mark.parametrize("obs_mode,env_id", [
    pytest.param(m, e, marks=[pytest.mark.slow] if (e == "SoftVTSpatialSoft-v1" or LEAK_MODES[m]) and
                 LEAK_MODES[m] != e else [])
    for m in LEAK_MODES for e in ENV_IDS])
def test_no_evaluator_quantity_reaches_the_observation(obs_mode, env_id):
    env = gym.make(env_id, task_id=4, obs_mode=obs_mode)
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.settle_info["settled"]  # the default run's settling check (every task's is slow)
    obs, *_ = env.step(_hold_still(env))
    u = env.unwrapped
    secrets = []
    for name, ev in u.evaluator_state().items():
        if name == "pad_wrenches":
            continue
        # A rigid twin has no modulus (None); its pose is carried by its nodes and centroid.
        secrets += [ev["centroid"], ev["nodes"][::7].ravel(), ev["x0"][::7].ravel(),
                    [x for x in (ev["deformation"], ev["youngs_modulus"], ev["mass"]) if x is not None]]
    secrets = np.concatenate([np.ravel(s) for s in secrets]).astype(np.float32)
    for path, leaf in _leaves(obs):
        assert not any(k in path.lower() for k in EVALUATOR_KEYWORDS), path
        assert not isinstance(leaf, str), f"{path}: observations hold arrays only (the instruction is the env's)"
        values = leaf.cpu().numpy() if isinstance(leaf, torch.Tensor) else np.asarray(leaf)
        if path.endswith("xyzw"):
            # A camera's points see the object's surface (to the position texture's millimetre): none is a
            # node, copied over (closer than a micrometre to one: chance, for a few thousand points, ~1e-4).
            nodes = np.concatenate([ev["nodes"] for n, ev in u.evaluator_state().items() if n != "pad_wrenches"])
            gap = cKDTree(nodes.astype(np.float32)).query(values[0, :, :3])[0].min()
            assert gap > 1e-6, f"{path} holds FEM node positions"
            continue
        if values.dtype.kind != "f" or path.endswith("sensor_param") or "sensor_param" in path or \
                path.endswith("/normal"):
            continue  # images (uint8), unit normals and camera intrinsics/extrinsics carry no object state
        v = values.ravel()
        # No float in the observation equals an evaluator quantity (node coordinates, centroid,
        # E, mass, D) to 1e-7 relative: nothing was copied over.
        close = np.isclose(v[:, None], secrets[None, :], rtol=1e-7, atol=0.0) & (np.abs(secrets[None, :]) > 1e-3)
        assert not close.any(), f"{path} contains evaluator values"
    env.close()


def test_tactile_observation_has_both_fingers_and_reacts_to_a_grasp():
    from mani_skill_softvt.expert.grasp_script import GraspPlan, run_grasp_script

    env = gym.make("SoftVTObjectRigid-v1", task_id=3, obs_mode="rgb+tactile")
    obs, _ = env.reset(seed=0)
    for side in ("left", "right"):
        t = obs["tactile"][side]
        assert t["rgb"].shape == (1, 240, 320, 3) and t["marker_current"].shape == (1, 99, 2)
        assert t["depth"].shape == (1, 240, 320) and t["depth"].dtype == torch.int16
        # Open gripper, nothing touches the gel: the sensor's reference frame, markers at rest, no indentation.
        assert torch.equal(t["marker_current"], t["marker_initial"])
        assert not t["depth"].any()
    plan = GraspPlan(closure=0.8)
    plan.steps = {**plan.steps, "lift": 0, "hold": 0, "lower": 0, "open": 0, "retreat": 0}
    run_grasp_script(env, plan)
    obs = env.unwrapped.get_obs()
    for side in ("left", "right"):
        t = obs["tactile"][side]
        assert not torch.equal(t["rgb"], obs_before(env, side)), side
        # The depth observation is the frame's indentation in micrometres: the pressed patch, within
        # the gel's thickness, and nothing beyond the contact but the upsampling's one gel cell (2 px).
        frame = env.unwrapped.tactile_frames()[side]
        depth_um = t["depth"].numpy()[0].astype(np.float64)
        np.testing.assert_allclose(depth_um, frame.depth * 1e6, atol=0.5)
        near_contact = cv2.dilate(frame.contact.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        assert 0 < depth_um.max() <= GEL_THICKNESS * 1e6 and not depth_um[~near_contact].any(), side
    env.close()


def obs_before(env, side):
    return torch.from_numpy(env.unwrapped.tactile_background(side)[None])


@pytest.mark.slow  # three rendered soft episodes; the evaluator's camera sizes are checked by default
def test_cameras_render_only_for_the_observations_a_policy_reads():
    """rollout(skip_unread_cameras=True), as the evaluator runs it: a chunk's inner steps and the
    steps whose images the policy declines render no camera, and the episode is the same bit for
    bit as with every camera rendered (rendering reads the scene, never changes it); the GelSights
    capture every step either way."""
    from mani_skill_softvt.contracts.policy import Policy
    from mani_skill_softvt.rollout import Observer, rollout

    class Chunks(Policy):  # chunks of 3 "hold still"; asks for images after every other call
        def reset(self, instruction, seed):
            self.calls, self.seen = 0, []

        def act(self, obs):
            self.seen.append(bool(obs["sensor_data"]))
            self.calls += 1
            return np.stack([self.hold] * 3)

        def needs_next_images(self):
            return self.calls % 2 == 0

    class Watch(Observer):
        def on_reset(self, env, obs, info):
            self.cameras, self.images, self.tactile = [], [], []

        def on_step(self, env, action, obs, info):
            self.cameras.append(sorted(obs["sensor_data"]))
            self.images.append({c: v["rgb"].clone() for c, v in obs["sensor_data"].items()})
            self.tactile.append({s: {k: v.clone() for k, v in t.items()} for s, t in obs["tactile"].items()})
            return len(self.cameras) == 9

    runs = []
    for skip in (False, True):
        env = gym.make("SoftVTObjectSoft-v1", task_id=3, obs_mode="rgb+tactile")
        env.reset(seed=0)
        policy, watch = Chunks(), Watch()
        policy.hold = _hold_still(env, closure=0.5)
        ep = rollout(env, policy, seed=0, replan_steps=3, observers=[watch], skip_unread_cameras=skip)
        assert ep.termination == "stopped" and ep.steps == 9
        runs.append((policy.seen, watch, env.unwrapped.get_state_dict(), ep.obs))
        if skip:  # a reset to given states and obs after a step without cameras still shows them
            obs, _ = env.reset(options={"reset_to_env_states": {"env_states": runs[0][2], "obs": runs[0][3]}})
            assert sorted(obs["sensor_data"]) == ["base_camera", "hand_camera"]
        env.close()
    (seen_all, all_, state_all, _), (seen, skipped, state, last) = runs
    assert seen_all == [True] * 3 and all(c == ["base_camera", "hand_camera"] for c in all_.cameras)
    # Rendered: the reset's (call 1), and step 6, after call 2 asked for it; call 3 did not ask.
    assert seen == [True, False, True]
    assert [bool(c) for c in skipped.cameras] == [i == 6 for i in range(1, 10)]
    for c, image in skipped.images[5].items():  # step 6: the same picture as with every step rendered
        assert torch.equal(image, all_.images[5][c]), c
    for a, b in zip(all_.tactile, skipped.tactile):
        for side in a:
            for k in a[side]:
                assert torch.equal(a[side][k], b[side][k]), (side, k)
    flat = lambda d, p="": [x for k, v in d.items() for x in (flat(v, p + k + "/") if isinstance(v, dict) else [(p + k, v)])]
    for (ka, va), (kb, vb) in zip(flat(state_all), flat(state)):
        assert ka == kb and torch.equal(va, vb), ka
    assert last["sensor_data"] == {} and last["agent"]["qpos"].shape == (1, 9)


@pytest.mark.slow
def test_an_expert_episode_scores_the_same_with_the_unread_cameras_skipped():
    """A whole soft-object episode with contact (the expert grasps, lifts and places the cube) whose
    policy declines every other frame's images is the same record as with every camera rendered:
    deformation trace, R_max, success, steps."""
    from mani_skill_softvt.data.seeds import id_seed
    from mani_skill_softvt.evaluation.policies import ScriptedExpertPolicy
    from mani_skill_softvt.evaluation.runner import run_episode
    from mani_skill_softvt.evaluation.wrapper import make_env

    def blinking():  # the package's expert (only its own policies may plan on the env), declining every other frame
        expert = ScriptedExpertPolicy()
        calls = []
        expert.needs_next_images = lambda: calls.append(1) or len(calls) % 2 == 0
        return expert

    episode = {"suite": "object_soft", "task_id": 3, "condition": "id", "seed": id_seed(3, 0)}
    records, rendered, skips = [], [], []
    for on_step in (lambda obs, info: rendered.append(bool(obs["sensor_data"])), None):
        env = make_env("object_soft", 3, obs_mode="rgb+tactile", camera_size=(32, 32))
        skip = env.unwrapped.skip_cameras_next_step
        env.unwrapped.skip_cameras_next_step = lambda skip=skip: skips.append(1) or skip()
        records.append(run_episode(env, blinking(), episode, on_step=on_step))
        env.close()
    drop = ("wall_s", "record_sha256")
    full, skipped = ({k: v for k, v in r.items() if k not in drop} for r in records)
    assert full["success"] and full["steps"] > 100 and full["r_max"] > 0.1  # it squeezed the cube
    assert all(rendered)  # a video's run renders every step and does not ask
    # The expert's chunks of 8 leave 7 unread, and it declines every other chunk's last.
    assert len(skips) >= full["steps"] * 7 // 8
    assert skipped == full


def _press_into_the_basket(env, seed: int, offset=(-0.04, -0.02), steps=60, options=None) -> list[bytes]:
    """The half-closed hand lowered onto the basket's rim until the fingers press its wall and the
    table; the bytes of every state of the episode (ManiSkill's flat state, FEM included)."""
    env.reset(seed=seed, options=options)
    u = env.unwrapped
    target = u.target.pose.p[0, :2].cpu().numpy() + np.asarray(offset)
    states = []
    for i in range(steps):
        env.step(ee_action(np.array([*target, max(0.14 - 0.004 * i, 0.0)]), 0.5, yaw=0.3))
        states.append(u.get_state().numpy().tobytes())
    return states


def _first_difference(a: list[bytes], b: list[bytes]) -> int | None:
    """The first step at which two episodes' states differ in any bit (None: none does)."""
    return next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), None)


# The goldens keep an episode's bits in the default run.
@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_an_episode_is_the_same_bits_in_a_fresh_env_and_after_other_episodes():
    """An episode must not depend on what ran before it in the same env: the evaluator's resume
    and ``--reproduce`` run episodes in other orders. PhysX keeps contact state across a plain
    reset: on the development machine the second run of this episode in one env parted from the
    first at step 32, when a finger presses the basket (a Diffusion Policy's soft-cube episode
    parted so at step 153, a finger's impulse on the basket 0.3766 against 0.3753 N s). Every
    reset therefore rebuilds the scene."""
    envs = []

    def make(**kw):
        envs.append(gym.make("SoftVTObjectSoft-v1", task_id=3, obs_mode="state_dict", **kw))
        return envs[-1]

    try:
        fresh = _press_into_the_basket(make(), seed=7)
        env = make()
        # Another seed pressing elsewhere under an OOD condition, then this episode twice.
        _press_into_the_basket(env, seed=8, offset=(0.05, 0.0), options={"ood": "mass_x2.5"})
        assert _first_difference(_press_into_the_basket(env, seed=7), fresh) is None
        assert _first_difference(_press_into_the_basket(env, seed=7), fresh) is None
    finally:
        for e in envs:
            e.close()


@pytest.mark.slow  # a diagnostic of the reason above, not a guarantee: three more soft episodes
def test_without_the_per_reset_rebuild_physx_history_shows_here_or_a_warning_says_not():
    import warnings

    envs = [gym.make("SoftVTObjectSoft-v1", task_id=3, obs_mode="state_dict"),
            gym.make("SoftVTObjectSoft-v1", task_id=3, obs_mode="state_dict", reconfiguration_freq=0)]
    try:
        fresh = _press_into_the_basket(envs[0], seed=7)
        # Whether the plain reset shows the dependence here depends on how the machine rounds.
        _press_into_the_basket(envs[1], seed=7)
        if _first_difference(_press_into_the_basket(envs[1], seed=7), fresh) is None:
            warnings.warn("without the per-reset rebuild this scenario reproduced on this machine: the test "
                          "shows no PhysX history here", stacklevel=1)
    finally:
        for e in envs:
            e.close()


def test_a_malformed_action_is_refused_before_the_simulation_sees_it():
    import torch

    from mani_skill_softvt.tasks.robot import validate_action

    for bad, message in ((np.full(7, np.nan), "NaN or inf"), (["x"] * 7, "must be numbers"),
                         (np.zeros(6), "shape \\(6,\\), expected \\(7,\\) for control mode 'pd_ee_pose'")):
        with pytest.raises(ValueError, match=message):
            validate_action(bad, (7,), "pd_ee_pose")
    assert validate_action([0.1] * 7, (7,), "pd_ee_pose").dtype == np.float32  # a sequence becomes an array
    t = torch.zeros(1, 7)
    assert validate_action(t, (7,), "pd_ee_pose") is t and validate_action(None, (7,), "pd_ee_pose") is None
