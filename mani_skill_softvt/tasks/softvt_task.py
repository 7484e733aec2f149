"""SoftVTBench pick-and-place: one parametrised task, registered once per suite.

``SoftVTObjectSoft-v1``, ``SoftVTSpatialSoft-v1``, ``SoftVTObjectRigid-v1`` and
``SoftVTSpatialRigid-v1`` are this class with ``suite`` preset; ``task_id`` (0-9) picks the
object and instruction (see :func:`mani_skill_softvt.tasks.suites.list_tasks`).

**Task Description:** follow the language instruction: pick up the named object (Object
suites) or the named one of two identical instances (Spatial suites, "left"/"right" as seen
from the robot, i.e. +y / -y) and place it in the basket (Object suites) or on the plate
(Spatial suites). Object suites use the task's asset, Spatial suites two instances of it; the
rigid suites use the rigid twins with the same layouts and instructions.

**Randomizations** (all from the episode seed; OOD options never change them):
- object placement: xy inside a per-suite support rectangle, yaw within +-15 deg;
- target placement: the basket's / plate's xy inside its support rectangle;
- robot initialisation: the rest joint configuration plus N(0, 0.02 rad) per arm joint.

**Success Conditions:** the instructed instance is at rest (centroid slower than 2 cm/s), not
held, with its centroid above the target region and its lowest node inside the region's
height band. The other instance in the target does not count.

**Failure (early termination):** ``dropped``: the object fell while not held outside the
target (downward centroid speed above 0.25 m/s), or left the table.

**Observation** (``obs_mode``): every mode ManiSkill parses. ``state`` (the default: flat
proprioception), ``state_dict``, ``none``; the cameras (third-person ``base_camera`` and wrist
``hand_camera`` at 224x224) in ``rgb``, ``depth`` (int16 mm), ``segmentation`` (int16 ids of the
env's ``segmentation_id_map``; each soft object one id, named as its rigid twin), ``position``,
``normal``, their ``+`` combinations (with ``+state``), ``rgbd``, ``pointcloud`` (world ``xyzw``,
``rgb``, ``segmentation``) and ``sensor_data``; each camera mode also with ``+tactile`` (both
fingers' GelSight images and marker fields). The soft objects are drawn as they are each step, so
their depth, points and masks follow the squeeze. ``agent`` holds joint positions/velocities,
``extra`` the TCP pose and the jaw width. Observations are arrays only: the instruction is the
env's (:attr:`SoftVTTaskEnv.instruction`). Nothing evaluator-only (FEM nodes, object poses,
deformation, materials) is in any mode; the evaluator reads the env's evaluator-only accessors
(:meth:`SoftBodyEnv.evaluator_state`). The contract: :mod:`mani_skill_softvt.contracts.observations`.

**Action** (``control_mode``): ``pd_ee_pose`` (the default; 7-D: absolute TCP position in the robot
base frame, axis-angle orientation, gripper closure in [0, 1]), ManiSkill's ``pd_ee_delta_pose`` (7-D),
``pd_joint_pos`` and ``pd_joint_delta_pos`` (8-D) with ManiSkill's gripper action (in [-1, 1], 1 open,
-1 closed), each also ``<mode>_binary`` (open/close, close until the 10 N force limit); see
:mod:`mani_skill_softvt.tasks.robot`.

**Env ids:** the suite's (``SoftVTObjectSoft-v1``, ``task_id`` an env kwarg) and one per task
(``SoftVTObjectSoft-Task3-v1``: ``task_id`` preset), for tools that pass an env id and no kwargs.

**Reward** (``reward_mode``): ``sparse`` (the default, as the benchmark is scored by success): 1 on
success. ``dense``: staged as in ManiSkill's tabletop tasks (:mod:`~mani_skill_softvt.tasks.rewards`),
each stage at most 1: reach (TCP to the instructed object's centroid), grasp, place (centroid to the
target region's centre, while grasped or once in the target), release (the object coming to rest
in the target, let go); success gives the maximum, 5. Deformation beyond the object's calibrated
tolerance costs up to 1: tanh(max(0, R_t - 1)) with R_t = D_t / tau_o, tau_o from the calibration
card of the object's soft asset (rigid twins: their soft asset's), loaded on the first dense
reward (``calibration_dir`` to read cards elsewhere). ``normalized_dense``: ``dense`` / 5, in [0, 1].
``none``: 0. **Episode end:** success, drop, or 300 control steps.

**Reset options:** ``ood`` (one of :data:`~mani_skill_softvt.tasks.suites.OOD_CONDITIONS`) or
the single factors ``light_intensity`` (nominal 135), ``mass_scale``, ``youngs_modulus_scale``;
in the Spatial suites ``swap_side`` (True: the instruction names the other instance and success
requires that one; the scene, seed and initial state are the ID episode's: the side-swap condition);
``placement_scale`` (default 1): the object's and the target's placement ranges scaled about their
centres, the same random draws (the difficulty study: how much the ranges explain).
"""

from __future__ import annotations

import numpy as np
import sapien
import torch
from mani_skill.sensors.camera import CameraConfig
from mani_skill.utils import sapien_utils
from mani_skill.utils.registration import register_env

from ..assets import load_card, load_prop
from ..calibration.cards import load_calibration_card
from ..paths import CALIBRATION_DIR
from . import constants as C
from . import rewards
from ..contracts.actions import GRIPPER_ACTION_VERSION, GRIPPER_ACTION_VERSIONS
from .soft_body_env import ObjectSpec, PropCollider, SoftBodyEnv
from .suites import NUM_TASKS, SUITES, TaskSpec, swapped_side, task_spec


class SoftVTTaskEnv(SoftBodyEnv):
    """Pick-and-place of a soft (or rigid-twin) object named by a language instruction."""

    # ManiSkill's default reward mode is the first: sparse, the benchmark's success.
    SUPPORTED_REWARD_MODES = ("sparse", "dense", "normalized_dense", "none")

    def __init__(self, *args, suite: str = "object_soft", task_id: int = 0, obs_mode: str | None = None,
                 robot_init_qpos_noise: float = C.ROBOT_INIT_QPOS_NOISE, calibration_dir: str | None = None,
                 env_task_id: int | None = None, gripper_action_version: int = GRIPPER_ACTION_VERSION, **kwargs):
        # env_task_id: the task a per-task env id names (registered with it); another task_id would make
        # the env disagree with its own id, and with every file that records that id.
        if env_task_id is not None and task_id != env_task_id:
            s = SUITES[suite]
            raise ValueError(f"{s.task_env_id(env_task_id)} is task {env_task_id}, but task_id={task_id!r} was "
                             f"passed; make {s.task_env_id(task_id) if task_id in range(NUM_TASKS) else s.env_id} "
                             f"instead, or {s.env_id} with task_id")
        # gripper_action_version: the gripper encoding a recorded file's actions are in (its json's
        # env kwargs); the env runs the current one only (mani_skill_softvt.tasks.robot).
        if gripper_action_version != GRIPPER_ACTION_VERSION:
            why = GRIPPER_ACTION_VERSIONS.get(gripper_action_version, "this version of mani_skill_softvt does not know "
                                              "it; upgrade the package or record the file again")
            raise ValueError(f"gripper_action_version={gripper_action_version!r} (a recorded file's env kwargs): "
                             f"{why.format(path='FILE.h5')}")
        self.task: TaskSpec = task_spec(suite, task_id)
        self._instructed: TaskSpec = self.task  # the task as this episode instructs it (swap_side: the other side)
        self._placement_scale = 1.0  # the episode's placement ranges, scaled (reset option placement_scale)
        self.asset_card = load_card(self.task.asset_id)
        self.robot_init_qpos_noise = robot_init_qpos_noise
        self.calibration_dir = CALIBRATION_DIR if calibration_dir is None else calibration_dir
        self._calibration_card = None  # loaded on first use (the DSR scorer, the expert, the dense reward)
        super().__init__(*args, obs_mode=obs_mode, **kwargs)

    @property
    def instruction(self) -> str:
        """The episode's language instruction. It belongs to the env and to each recorded episode, not to
        the observation: ManiSkill's tools (RecordEpisode, replay_trajectory, vector envs' shared memory,
        its baseline loaders) take observations of arrays only."""
        return self._instructed.instruction

    @property
    def target_instance(self) -> str:
        """Name of the instructed soft object: "object", or "left"/"right" in Spatial suites."""
        return self._instructed.side or "object"

    def reset(self, seed=None, options=None):
        options = dict(options or {})
        swap = options.pop("swap_side", False)
        if not isinstance(swap, bool):
            raise ValueError(f"reset option swap_side={swap!r}: give True or False")
        scale = options.pop("placement_scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 < scale <= C.MAX_PLACEMENT_SCALE:
            raise ValueError(f"reset option placement_scale={scale!r}: give a number in (0, {C.MAX_PLACEMENT_SCALE}] "
                             "(1: the benchmark's ranges)")
        self._placement_scale = float(scale)
        # Checked before the scene is rebuilt, and kept for the episode (the layout draws no side).
        try:
            self._instructed = swapped_side(self.task) if swap else self.task
        except ValueError as e:
            raise ValueError(f"reset option swap_side: {e}") from None
        return super().reset(seed=seed, options=options)

    # ------------------------------------------------------------------ scene
    def _object_specs(self):
        names = ["left", "right"] if self.task.side else ["object"]
        return [ObjectSpec.from_card(n, self.asset_card) for n in names]

    def _load_props(self, options):
        prop = load_prop(self.task.target)
        b = self.scene.create_actor_builder()
        for path in prop.collision_files:
            b.add_convex_collision_from_file(str(path))
        b.add_visual_from_file(str(prop.visual_file), material=sapien.render.RenderMaterial(
            base_color=list(prop.color), roughness=0.8))
        b.initial_pose = sapien.Pose(p=[0.0, 0.0, -1.0])
        self.target = b.build_kinematic(name=self.task.target)
        self.target_region = prop.regions["interior" if self.task.target == "basket" else "top"]
        return [PropCollider(self.task.target, self.target._bodies[0], convex_parts=prop.convex_parts(),
                             friction=prop.friction)]

    @property
    def _default_sensor_configs(self):
        pose = sapien_utils.look_at(eye=C.BASE_CAMERA_EYE, target=C.BASE_CAMERA_TARGET)
        hand = self.agent.robot.links_map["camera_link"] if "camera_link" in self.agent.robot.links_map \
            else self.agent.robot.links_map["panda_hand"]
        shader = self.obs_mode_spec.shader_pack
        return [
            CameraConfig("base_camera", pose, C.CAMERA_SIZE, C.CAMERA_SIZE, C.BASE_CAMERA_FOV, 0.01, 100,
                         shader_pack=shader),
            CameraConfig("hand_camera", sapien.Pose(p=C.WRIST_CAMERA_OFFSET, q=C.WRIST_CAMERA_Q), C.CAMERA_SIZE,
                         C.CAMERA_SIZE, np.pi / 2, 0.01, 100, mount=hand, shader_pack=shader),
        ]

    @property
    def _default_human_render_camera_configs(self):
        pose = sapien_utils.look_at(eye=C.RENDER_CAMERA_EYE, target=C.RENDER_CAMERA_TARGET)
        return CameraConfig("render_camera", pose, 512, 384, 1.0, 0.01, 100)

    # ------------------------------------------------------------------ episode
    def _initialize_task(self, env_idx, options):
        # The layout is drawn first and always in the same order, so OOD resets with the ID seed
        # reproduce the ID initial state exactly.
        rng = self._episode_rng
        layout = C.LAYOUTS[self.task.target]
        qpos = C.ROBOT_REST_QPOS.copy()
        qpos[:7] += rng.normal(0.0, self.robot_init_qpos_noise, 7)
        k = self._placement_scale  # 1 but in the difficulty study; the draws are the same either way
        obj_xy = np.asarray(layout["object_center"]) + rng.uniform(-1, 1, 2) * np.asarray(layout["object_half_range"]) * k
        yaws = rng.uniform(-C.OBJECT_YAW_RANGE, C.OBJECT_YAW_RANGE, 2)
        tgt_xy = np.asarray(layout["target_center"]) + rng.uniform(-1, 1, 2) * np.asarray(layout["target_half_range"]) * k
        self.agent.reset(torch.as_tensor(qpos[None], dtype=torch.float32))
        self.target.set_pose(sapien.Pose(p=[tgt_xy[0], tgt_xy[1], 0.0]))
        poses = {}
        for k, name in enumerate(self.object_names):
            xy = obj_xy + (np.array([0.0, {"left": 1.0, "right": -1.0}[name] * C.SPATIAL_HALF_GAP])
                           if self.task.side else 0.0)
            q = np.array([np.cos(yaws[k] / 2), 0.0, 0.0, np.sin(yaws[k] / 2)])
            poses[name] = np.array([xy[0], xy[1], 0.0, *q])
        return poses

    # ------------------------------------------------------------------ evaluation
    def _object_kinematics(self, name: str) -> dict:
        nodes = self.soft_nodes(name)
        vel = self.soft_node_velocities(name)
        return {"centroid": nodes.mean(axis=0), "min_z": float(nodes[:, 2].min()),
                "velocity": vel.mean(axis=0), "nodes": nodes}

    def _in_target(self, kin: dict) -> bool:
        lo, hi = (np.asarray(v) for v in self.target_region)
        p = self.target.pose.p[0].cpu().numpy().astype(np.float64)
        c = kin["centroid"] - p
        inside_xy = np.all(c[:2] >= lo[:2]) and np.all(c[:2] <= hi[:2])
        z = kin["min_z"] - p[2]
        return bool(inside_xy and lo[2] - C.REGION_Z_TOLERANCE <= z <= hi[2])

    def _is_grasped(self, kin: dict) -> bool:
        forces = self.pad_forces().values()
        tcp = self.agent.tcp.pose.p[0].cpu().numpy()
        near = np.linalg.norm(kin["centroid"] - tcp) < C.GRASP_CENTROID_DISTANCE
        return bool(min(forces) > C.GRASP_MIN_FORCE and near)

    def evaluate(self):
        out = {}
        for name in self.object_names:
            kin = self._object_kinematics(name)
            grasped = self._is_grasped(kin)
            in_target = self._in_target(kin)
            at_rest = float(np.linalg.norm(kin["velocity"])) < C.REST_SPEED
            off_table = kin["centroid"][2] < -C.OFF_TABLE_DEPTH or np.any(
                np.abs(kin["centroid"][:2]) > np.asarray(C.TABLE_HALF_EXTENTS[:2]))
            falling = kin["velocity"][2] < -C.DROP_SPEED and not grasped and not in_target
            out[name] = dict(grasped=grasped, in_target=in_target, at_rest=at_rest, dropped=bool(off_table or falling))
        t = out[self.target_instance]
        success = t["in_target"] and t["at_rest"] and not t["grasped"]
        dropped = any(o["dropped"] for o in out.values())
        info = {
            "success": success,
            "fail": dropped and not success,
            "is_grasped": t["grasped"],
            "dropped": dropped,
            "in_target": t["in_target"],
            "other_in_target": any(o["in_target"] for n, o in out.items() if n != self.target_instance),
        }
        return {k: torch.tensor([bool(v)]) for k, v in info.items()}

    def compute_sparse_reward(self, obs, action, info):
        return info["success"].float()

    @property
    def calibration_card(self):
        """The calibration card of the instructed object's soft asset (a rigid twin's soft asset):
        its envelope and tau_o. Loaded once, on first use, so that an env nobody scores needs no card;
        the DSR scorer, the expert and the dense reward all read this one."""
        if self._calibration_card is None:
            self._calibration_card = load_calibration_card(self.task.soft_asset_id, self.calibration_dir,
                                                           physics=self.physics)
        return self._calibration_card

    @property
    def deformation_tolerance(self) -> float:
        """tau_o of the instructed object, from :attr:`calibration_card`."""
        try:
            return self.calibration_card.tau_o
        except (FileNotFoundError, ValueError) as e:
            t = self.task
            twin = f" (the soft asset of the rigid twin '{t.asset_id}')" if t.rigid else ""
            raise type(e)(f"the dense reward of {SUITES[t.suite].env_id} task {t.task_id} penalises "
                          f"deformation beyond the tolerance tau_o of '{t.soft_asset_id}'{twin}, from its "
                          f"calibration card: {e}; or make the env with reward_mode='sparse'") from None

    def _target_region_centre(self) -> np.ndarray:
        lo, hi = (np.asarray(v, np.float64) for v in self.target_region)
        return self.target.pose.p[0].cpu().numpy().astype(np.float64) + 0.5 * (lo + hi)

    def compute_dense_reward(self, obs, action, info):
        # Evaluator-only quantities (centroid, velocity, D_t, collapses) shape the reward; none reaches the observation.
        name = self.target_instance
        kin = self._object_kinematics(name)
        tcp = self.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64)
        reward = rewards.staged_reward(
            tcp_to_object=np.linalg.norm(kin["centroid"] - tcp),
            object_to_target=np.linalg.norm(kin["centroid"] - self._target_region_centre()),
            object_speed=np.linalg.norm(kin["velocity"]),
            grasped=info["is_grasped"], in_target=info["in_target"], success=info["success"],
            deformation_ratio=self.deformation(name) / self.deformation_tolerance,
            collapsed=self.collapsed_tets() > 0,
        )
        return reward.reshape(1).to(self.device)

    def compute_normalized_dense_reward(self, obs, action, info):
        return rewards.normalized_reward(self.compute_dense_reward(obs, action, info))

    # ------------------------------------------------------------------ observations
    def _get_obs_extra(self, info):
        width = torch.tensor([[self.gripper_width]], dtype=torch.float32)
        return {"tcp_pose": self.agent.tcp.pose.raw_pose, "gripper_width": width}


# Each suite's id takes task_id as an env kwarg; beside it one id per task (SoftVTObjectSoft-Task3-v1) for
# tools that pass an env id and no kwargs. The gripper version is a registered kwarg so that every
# file any RecordEpisode writes (ManiSkill's replay's too) records it in its env kwargs.
for _suite in SUITES.values():
    register_env(_suite.env_id, max_episode_steps=C.MAX_EPISODE_STEPS, suite=_suite.name,
                 gripper_action_version=GRIPPER_ACTION_VERSION)(SoftVTTaskEnv)
    for _k in range(NUM_TASKS):
        register_env(_suite.task_env_id(_k), max_episode_steps=C.MAX_EPISODE_STEPS, suite=_suite.name, task_id=_k,
                     env_task_id=_k, gripper_action_version=GRIPPER_ACTION_VERSION)(SoftVTTaskEnv)
