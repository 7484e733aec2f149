"""Base class of every SoftVT environment: ManiSkill scene + Newton FEM soft bodies in lockstep.

Subclasses declare their objects (:meth:`SoftBodyEnv._object_specs`), load the rest
of the scene (:meth:`SoftBodyEnv._load_props`) and place things per episode
(:meth:`SoftBodyEnv._initialize_task`). This class owns what every task shares:

- the Panda (``panda_softvt``: force-limited gripper, absolute end-effector pose control);
- the Newton world with one tetrahedral body per soft object, and colliders mirrored from
  SAPIEN (finger pads, hand, table top, any prop that declares a collider);
- lockstep stepping (SAPIEN and Newton at ``SIM_FREQ``) with contact wrenches fed back to the
  finger links;
- a settle routine before each episode; the settled nodes are x_0 of the deformation metric;
- drawing the deformed surface in SAPIEN after every control step (cameras see the squeeze);
- env state save/restore including FEM node positions and velocities;
- the physical factors of a reset (``options``: an ``ood`` condition or ``youngs_modulus_scale``,
  ``mass_scale``, ``light_intensity``), resolved once and applied in one place
  (:meth:`SoftBodyEnv.apply_factors`), without rebuilding kernels;
- rigid twins instead of soft objects (``ObjectSpec.rigid``): PhysX rigid bodies with the card's
  convex parts, mass, friction and colour, read through the same node accessors
  (:mod:`mani_skill_softvt.physics.rigid`); a scene of twins builds no Newton world at all;
- a GelSight Mini on each finger, a ManiSkill sensor configured like the cameras
  (:attr:`SoftBodyEnv._default_tactile_configs`), observed in ``+tactile`` obs modes;
- instability detection (NaN, inverted tets, exploding velocities) after every control step.

Evaluator-only state (FEM nodes, object poses, deformation, material parameters) is exposed
through cheap public accessors (:meth:`soft_nodes`, :meth:`settled_nodes`, :meth:`pad_forces`, ...)
and :meth:`SoftBodyEnv.evaluator_state`, never through observations.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sapien
import torch
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.sensors.camera import Camera, CameraConfig
from mani_skill.utils import sapien_utils
from mani_skill.utils.common import to_numpy
from mani_skill.utils.structs.types import SimConfig

from ..assets.tetmesh import embed_points, surface_of_tets
from ..physics import constants as PC
from ..physics.coupling import MirroredBody, SapienNewtonCoupling
from ..physics.deformation import deformation
from ..physics.fem import SoftBodyWorld, SoftMaterial, vbd_schedule
from ..physics.rigid import RigidObject, rigid_nodes
from ..physics.transforms import pose_wxyz_to_matrix
from ..tactile.gelsight import GelSight, GelSightConfig
from ..tactile.geometry import contact_polygons, polygons_mask
from ..tactile.sensor import finger_pad_frame, world_to_pad
from . import constants as C
from .robot import PandaSoftVT  # noqa: F401  (registers the agent)
from .suites import FACTOR_OPTIONS, PhysicalFactors, resolve_factors

# Reset options: the episode's physical factors, and ManiSkill's own.
RESET_OPTIONS = frozenset({"ood", *FACTOR_OPTIONS, "reconfigure", "env_idx", "reset_to_env_states"})
FEEDBACK_LINKS = ("panda_leftfinger", "panda_rightfinger", "panda_hand")  # robot links objects push back on
TACTILE_SUFFIX = "+tactile"  # obs modes "rgb+tactile" etc.: the camera mode plus both fingers' GelSight


@dataclass
class ObjectSpec:
    """An object of a scene: rest tet mesh in its local frame (a rigid twin's evaluation nodes),
    material (None for a rigid twin), display colour; a rigid twin's PhysX body."""

    name: str
    vertices: np.ndarray  # (N, 3) m, local frame, bottom at z = 0
    tets: np.ndarray  # (M, 4)
    material: SoftMaterial | None
    color: tuple = (0.9, 0.85, 0.7, 1.0)
    # Visual meshes drawn deformed with the body: [(vertices (local), faces, rgba), ...].
    # Empty: draw the tet mesh's own boundary in ``color``.
    visual_parts: list = field(default_factory=list)
    # Rigid twin (PhysX rigid body): convex collision parts and visual meshes as files, mass, friction.
    rigid: bool = False
    rest_pose: tuple | None = None  # [p, q_wxyz] of the modelled shape in the body frame
    collision_files: tuple = ()
    visual_files: tuple = ()  # ((path, rgba), ...)
    mass: float | None = None
    density: float | None = None
    friction: float | None = None

    @classmethod
    def from_card(cls, name: str, card) -> "ObjectSpec":
        """Spec of an asset card (soft object or rigid twin)."""
        from ..assets.cards import read_obj

        v, t = card.tet_mesh()
        if card.rigid:
            # The twin's body frame rests it on a stable face (card.rest_pose); its nodes follow.
            return cls(name, rigid_nodes(v, np.asarray(card.rest_pose)), t, None, tuple(card.color), rigid=True,
                       rest_pose=card.rest_pose, collision_files=card.collision_files,
                       visual_files=tuple((path, rgba) for _, path, rgba in card.visual_parts), mass=card.mass,
                       density=card.density, friction=card.friction)
        parts = [(*read_obj(path), rgba) for _, path, rgba in card.visual_parts]
        return cls(name, v, t, card.material(), tuple(card.color), parts)


@dataclass
class PropCollider:
    """A SAPIEN body that soft objects can touch: boxes or convex parts in the body's frame."""

    name: str
    component: sapien.physx.PhysxRigidBaseComponent
    boxes: list | None = None  # [(half_extents, local_pose7), ...]
    convex_parts: list | None = None  # [(vertices, faces), ...] in the body frame
    friction: float = 0.8


class SoftBodyEnv(BaseEnv):
    """ManiSkill env with Newton FEM soft bodies. CPU simulation, one env per process."""

    SUPPORTED_ROBOTS = ["panda_softvt"]
    agent: PandaSoftVT

    def __init__(self, *args, robot_uids="panda_softvt", obs_mode: str | None = None, soft_sleep: bool = True,
                 **kwargs):
        if kwargs.get("num_envs", 1) != 1:
            raise ValueError(
                "SoftVT envs run one environment per process (Newton's CPU kernels and SAPIEN's CPU physics "
                "are single-threaded); use a process pool for parallel episodes"
            )
        # "auto" (ManiSkill's default, and what its tools pass) means the CPU here: there is no GPU path.
        if kwargs.get("sim_backend") in (None, "auto"):
            kwargs["sim_backend"] = "physx_cpu"
        if kwargs.get("render_backend") in (None, "auto"):
            kwargs["render_backend"] = "cpu"
        if kwargs["sim_backend"] not in ("physx_cpu", "cpu"):
            raise ValueError(f"SoftVT envs need sim_backend='physx_cpu' or 'auto' (got {kwargs['sim_backend']!r}): "
                             "the FEM coupling runs on the CPU, one env per process")
        self._world: SoftBodyWorld | None = None  # None in a scene of rigid twins
        self._coupling: SapienNewtonCoupling | None = None
        self._soft_index: dict[str, int] = {}  # soft object name -> Newton body index
        self._rigid: dict[str, RigidObject] = {}  # rigid twin name -> PhysX body
        self._render_entities: dict[str, sapien.Entity] = {}
        self._x0: dict[str, np.ndarray] = {}
        self._tactile: dict[str, GelSight] = {}  # side -> sensor, created with the scene's sensors
        self.settle_info: dict = {}
        self.soft_sleep = bool(soft_sleep)  # resting soft bodies that nothing moving nears skip the FEM
        self.factors = PhysicalFactors()
        self._lights, self._ambient = [], None  # the scene's lights at nominal intensity (set when loaded)
        obs_mode = obs_mode or "state"
        self.tactile_enabled = obs_mode.endswith(TACTILE_SUFFIX)
        super().__init__(*args, robot_uids=robot_uids, obs_mode=obs_mode.removesuffix(TACTILE_SUFFIX), **kwargs)
        # ManiSkill parsed the camera part ("rgb"); the public name keeps "+tactile".
        self._obs_mode = obs_mode

    # ------------------------------------------------------------------ config
    @property
    def _default_sim_config(self):
        # Lockstep rate: SAPIEN and Newton both at SIM_FREQ (see physics.coupling).
        return SimConfig(sim_freq=C.SIM_FREQ, control_freq=C.CONTROL_FREQ)

    @property
    def _default_sensor_configs(self):
        # Third-person view of the workspace at the policy resolution.
        pose = sapien_utils.look_at(eye=[0.35, 0.0, 0.45], target=[-0.1, 0.0, 0.05])
        return [CameraConfig("base_camera", pose, C.CAMERA_SIZE, C.CAMERA_SIZE, np.pi / 2, 0.01, 100)]

    @property
    def _default_human_render_camera_configs(self):
        pose = sapien_utils.look_at(eye=[0.28, 0.28, 0.25], target=[0.0, 0.0, 0.06])
        return CameraConfig("render_camera", pose, 384, 288, 1.0, 0.01, 100)

    @property
    def _default_tactile_configs(self) -> list[GelSightConfig]:
        """A GelSight Mini on each finger (configured like the cameras, built in the sensor setup)."""
        return [GelSightConfig(f"tactile_{side}", side=side, pad_half_extents=C.GEL_PAD_HALF_EXTENTS)
                for side in ("left", "right")]

    def _setup_sensors(self, options: dict):
        super()._setup_sensors(options)  # ManiSkill builds the cameras only
        self._tactile = {cfg.side: GelSight(cfg, self.contact_surface, lambda side=cfg.side: self.pad_pose(side),
                                            lambda pose, side=cfg.side: self.pad_normal_force(side, pose),
                                            deformable=not self._rigid)
                         for cfg in self._default_tactile_configs}
        if self.tactile_enabled:
            # Registered sensors are captured with the cameras; without "+tactile" they cost nothing.
            self._sensors.update({s.uid: s for s in self._tactile.values()})

    def get_sensor_images(self):
        # ManiSkill's scene pairs each registered sensor with a camera observation; the GelSights
        # have their own (render_mode="sensors" and "all" show them beside the cameras).
        obs = self._get_obs_sensor_data()
        images = {name: sensor.get_images(obs[name]) for name, sensor in self.scene.sensors.items() if name in obs}
        for name, sensor in self.scene.sensors.items():
            if isinstance(sensor, GelSight):
                images[name] = sensor.get_images()
        return images

    def _get_obs_sensor_data(self, apply_texture_transforms: bool = True) -> dict:
        if self._obs_mode != "none":
            return super()._get_obs_sensor_data(apply_texture_transforms)
        # Only render_mode="sensors"/"all" asks for sensor data in obs mode "none" (it observes
        # nothing). ManiSkill asks the cameras for the obs mode's textures, none here, and then
        # fails tiling an empty list; show them as in the other non-visual modes: colour and depth.
        for obj in self._hidden_objects:
            obj.hide_visual()
        self.scene.update_render(update_sensors=True, update_human_render_cameras=False)
        self.capture_sensor_data()
        return {name: sensor.get_obs(position=False, segmentation=False, apply_texture_transforms=apply_texture_transforms)
                for name, sensor in self.scene.sensors.items() if isinstance(sensor, Camera)}

    def get_sensor_params(self):
        # Tactile sensors have no camera parameters: keep sensor_param to the cameras' entries.
        return {k: v for k, v in super().get_sensor_params().items() if v}

    def _get_obs_with_sensor_data(self, info, apply_texture_transforms=True):
        obs = super()._get_obs_with_sensor_data(info, apply_texture_transforms)
        if self.tactile_enabled:
            obs["tactile"] = {side: sensor.get_obs() for side, sensor in self._tactile.items()}
        return obs

    def _load_agent(self, options: dict):
        super()._load_agent(options, sapien.Pose(p=C.ROBOT_BASE_POSE[:3], q=C.ROBOT_BASE_POSE[3:]))

    # ------------------------------------------------------------------ subclass hooks
    def _object_specs(self) -> list[ObjectSpec]:
        """The scene's objects: all soft, or all rigid twins."""
        raise NotImplementedError

    def _load_props(self, options: dict) -> list[PropCollider]:
        """Load task props (containers, distractors); return those soft objects can touch."""
        return []

    def _initialize_task(self, env_idx: torch.Tensor, options: dict) -> dict[str, np.ndarray]:
        """Place robot and props; return each object's rest pose [p, q_wxyz] (bottom at p)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ scene
    def _load_lighting(self, options):
        super()._load_lighting(options)
        scene = self.scene.sub_scenes[0]
        self._lights = [(e.components[0], np.array(e.components[0].color)) for e in scene.entities
                        if e.name == "directional_light"]
        self._ambient = np.array(self.scene.ambient_light)

    def _load_scene(self, options: dict):
        b = self.scene.create_actor_builder()
        he = C.TABLE_HALF_EXTENTS
        pose = sapien.Pose(p=[0.0, 0.0, -he[2]])
        b.add_box_collision(half_size=he, pose=pose)
        b.add_box_visual(half_size=he, pose=pose, material=sapien.render.RenderMaterial(base_color=[0.55, 0.42, 0.3, 1]))
        b.initial_pose = sapien.Pose()
        self.table = b.build_kinematic(name="table")
        specs = self._object_specs()
        if len({s.rigid for s in specs}) > 1:
            # One tactile model per frame (gel over an FEM surface, or force balance on a rigid one).
            raise ValueError(f"a scene's objects must be all soft or all rigid twins, got {[(s.name, s.rigid) for s in specs]}")
        self._specs = {s.name: s for s in specs}
        self._props = self._load_props(options)
        sub_scene = self.scene.sub_scenes[0]
        for k, spec in enumerate(s for s in specs if s.rigid):
            self._rigid[spec.name] = self._build_rigid_object(spec, k)
        for spec in (s for s in specs if not s.rigid):
            entity = sapien.Entity()
            entity.set_name(f"soft/{spec.name}")
            sub_scene.add_entity(entity)
            self._render_entities[spec.name] = entity
        self._boundary = {n: surface_of_tets(spec.tets) for n, spec in self._specs.items()}
        # What is drawn for each soft object: (rest vertices, faces, rgba, embedding tet index, weights).
        self._visuals = {}
        for n, spec in ((n, s) for n, s in self._specs.items() if not s.rigid):
            parts = spec.visual_parts or [(spec.vertices, surface_of_tets(spec.tets), spec.color)]
            self._visuals[n] = [(f, rgba, *embed_points(v, spec.vertices, spec.tets)) for v, f, rgba in parts]

    def _build_rigid_object(self, spec: ObjectSpec, k: int) -> RigidObject:
        """A rigid twin as ManiSkill builds any object: convex parts with the card's friction and
        density, visual meshes in their colours; then exactly the card's mass."""
        b = self.scene.create_actor_builder()
        material = sapien.physx.PhysxMaterial(static_friction=spec.friction, dynamic_friction=spec.friction,
                                              restitution=0.0)
        shape_pose = sapien.Pose(p=spec.rest_pose[:3], q=spec.rest_pose[3:])
        for path in spec.collision_files:
            b.add_convex_collision_from_file(str(path), pose=shape_pose, material=material, density=spec.density)
        for path, rgba in spec.visual_files:
            b.add_visual_from_file(str(path), pose=shape_pose,
                                   material=sapien.render.RenderMaterial(base_color=list(rgba), roughness=0.8))
        b.initial_pose = sapien.Pose(p=[0.0, 2.0 + 0.2 * k, 0.5])  # out of the way until the episode places it
        actor = b.build(name=spec.name)
        actor._bodies[0].set_solver_position_iterations(PC.RIGID_SOLVER_POSITION_ITERATIONS)
        return RigidObject(spec.name, actor._bodies[0], spec.vertices, spec.mass)

    def _after_reconfigure(self, options):
        super()._after_reconfigure(options)
        self._build_soft_world()

    def _build_soft_world(self):
        self._set_finger_inertia()
        soft = [s for s in self._specs.values() if not s.rigid]
        self._soft_index = {s.name: i for i, s in enumerate(soft)}
        if not soft:
            self._world = self._coupling = None  # rigid twins only: PhysX does everything
            return
        substeps, iterations = vbd_schedule(s.material.youngs_modulus for s in soft)
        world = SoftBodyWorld(substeps=substeps, iterations=iterations, sleeping=self.soft_sleep)
        for spec in soft:
            world.add_soft_body(spec.name, spec.vertices, spec.tets, spec.material, pose=np.array([0, 0, -1.0, 1, 0, 0, 0]))
        bodies = []
        robot_links = {link.name: link._objs[0] for link in self.agent.robot.get_links()}
        for side in ("left", "right"):
            name = f"panda_{side}finger"
            world.add_collider_box(
                name,
                C.FINGERTIP_HALF_EXTENTS,
                local_pose=np.array([*C.FINGERTIP_OFFSET[side], 1.0, 0.0, 0.0, 0.0]),
                friction=PC.FINGER_FRICTION,
                movable=True,
            )
            bodies.append(MirroredBody(name, robot_links[name], feedback=True))
        world.add_collider_convex("panda_hand", [_hand_collision_hull()], friction=PC.FINGER_FRICTION, movable=True)
        bodies.append(MirroredBody("panda_hand", robot_links["panda_hand"], feedback=True))
        he = C.TABLE_HALF_EXTENTS
        world.add_collider_box("table", he, local_pose=np.array([0, 0, -he[2], 1, 0, 0, 0]), friction=PC.TABLE_FRICTION)
        bodies.append(MirroredBody("table", self.table._bodies[0], feedback=False))
        for prop in self._props:
            if prop.boxes:
                world.add_collider_boxes(prop.name, prop.boxes, friction=prop.friction)
            else:
                world.add_collider_convex(prop.name, prop.convex_parts, friction=prop.friction)
            bodies.append(MirroredBody(prop.name, prop.component, feedback=False))
        world.finalize()
        self._world = world
        self._coupling = SapienNewtonCoupling(world, bodies)

    def _set_finger_inertia(self):
        """Give each finger the reflected inertia of the Franka gripper's geared drive.

        Contact forces return to SAPIEN one tick late, which is stable only while
        omega * dt < 2 with omega = sqrt(k_contact / m_finger). Against a stiff object (a rigid
        twin) k_contact ~ 1e5 N/m, so the URDF's bare 15 g finger would be thrown off the object;
        the geared gripper's reflected mass (~1 kg) is both realistic and stable.
        """
        for link in self.agent.robot.get_links():
            if link.name in ("panda_leftfinger", "panda_rightfinger"):
                body = link._objs[0]
                scale = C.FINGER_EFFECTIVE_MASS / body.mass
                body.set_mass(C.FINGER_EFFECTIVE_MASS)
                body.set_inertia(np.asarray(body.inertia) * scale)

    # ------------------------------------------------------------------ episode
    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        factors = resolve_factors(options)
        with torch.device(self.device):
            poses = self._initialize_task(env_idx, options)
        missing = set(self._specs) - set(poses)
        if missing:
            raise RuntimeError(f"_initialize_task did not place soft objects {sorted(missing)}")
        self.apply_factors(factors)
        for name in self._specs:
            self._place(name, poses[name])
        self.settle()
        self._update_render_meshes()
        for sensor in self._tactile.values():
            sensor.reset()

    def apply_factors(self, factors: PhysicalFactors) -> None:
        """The one place where an episode's physical factors take effect: Young's modulus and mass
        of every soft body (rescaled in place, no kernel rebuilt) and the light intensity."""
        if self._world is not None:
            self._world.scale_materials(youngs_modulus=factors.youngs_modulus_scale, mass=factors.mass_scale)
        for obj in self._rigid.values():
            obj.scale_mass(factors.mass_scale)  # a rigid body has no modulus to scale
        s = factors.light_intensity / C.NOMINAL_LIGHT_INTENSITY
        for light, nominal in self._lights:
            light.color = (nominal * s).tolist()
        if self._ambient is not None:
            self.scene.ambient_light = (self._ambient * s).tolist()
        self.factors = factors

    def live_light_intensity(self) -> float:
        """Light intensity read back from the renderer's ambient light (for audit receipts)."""
        return float(np.asarray(self.scene.ambient_light)[0] / self._ambient[0] * C.NOMINAL_LIGHT_INTENSITY)

    def settle(self, speed: float = C.SETTLE_SPEED, max_time: float = C.SETTLE_MAX_TIME) -> dict:
        """Let the soft objects come to rest on their supports (Newton only, robot frozen).

        The settled node positions become x_0 for the deformation metric, so the expert and the
        evaluator both start from the settled state (paper appendix, Assets). Rigid twins settle
        the same way in PhysX (a faceted ball placed on a vertex would roll away otherwise), with
        the robot held at its reset joint state.
        """
        world = self._world
        ticks, max_ticks = 0, int(max_time * C.SIM_FREQ)
        min_ticks = C.SIM_FREQ // 10
        if world is None:
            robot = self.agent.robot
            qpos, qvel = robot.get_qpos().clone(), robot.get_qvel().clone()
        while True:
            # Settling is not part of the episode's physics: drain kinetic energy so that
            # neutrally stable shapes (the ball) stop rocking instead of ringing for seconds.
            if world is None:
                self.scene.step()
                robot.set_qpos(qpos)
                robot.set_qvel(qvel)
                for obj in self._rigid.values():
                    obj.damp_velocities(C.SETTLE_VELOCITY_DAMPING)
                v = max(obj.speed() for obj in self._rigid.values())
            else:
                world.step()
                world.damp_velocities(C.SETTLE_VELOCITY_DAMPING)
                v = max(float(np.abs(world.particle_qd(i)).max()) for i in self._soft_index.values())
            ticks += 1
            if ticks >= min_ticks and v < speed:
                break
            if ticks >= max_ticks:
                break
        if world is None:
            self._x0 = {name: obj.nodes() for name, obj in self._rigid.items()}
            self.settle_info = {"ticks": ticks, "max_node_speed": v, "settled": v < speed}
            return self.settle_info
        world.check_health()
        world.wake()  # the episode starts awake; it may fall asleep in its own first ticks
        self._x0 = {name: world.particle_q(i) for name, i in self._soft_index.items()}
        self._coupling.wrenches[:] = 0.0
        world.time = 0.0
        self.settle_info = {"ticks": ticks, "max_node_speed": v, "settled": v < speed}
        return self.settle_info

    # ------------------------------------------------------------------ stepping
    def step(self, action):
        return super().step(self.validate_action(action))

    def reset(self, seed=None, options=None):
        unknown = sorted(set(options or {}) - RESET_OPTIONS)
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; SoftVT envs take {sorted(RESET_OPTIONS)}")
        return super().reset(seed=seed, options=options)

    def validate_action(self, action):
        """Reject malformed actions before anything in the simulation changes; return the action
        as ManiSkill takes it (arrays and tensors unchanged, sequences of numbers as float32 arrays)."""
        if action is None or isinstance(action, dict):
            return action
        a = np.asarray(to_numpy(action))
        if a.dtype.kind not in "fiu":
            raise ValueError(f"action must be numbers (7 floats: [x, y, z] position, [rx, ry, rz] axis-angle, "
                             f"gripper), got {type(action).__name__} of dtype {a.dtype}")
        shape = self.single_action_space.shape
        if a.shape not in (shape, (1, *shape)):
            raise ValueError(
                f"action has shape {a.shape}, expected {shape} for control mode '{self.control_mode}' "
                "([x, y, z] position, [rx, ry, rz] axis-angle, gripper)"
            )
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action contains NaN or inf: {a.ravel().tolist()}")
        return action if isinstance(action, (np.ndarray, torch.Tensor)) else a.astype(np.float32)

    def _before_simulation_step(self):
        if self._coupling is not None:
            self._coupling.before_sapien_step()

    def _after_simulation_step(self):
        if self._coupling is not None:
            self._coupling.after_sapien_step()

    def _after_control_step(self):
        if self._world is not None:
            self._world.check_health()
        self._update_render_meshes()

    def _update_render_meshes(self):
        for name, entity in self._render_entities.items():
            nodes = self._world.particle_q(self._soft_index[name])
            tets = self._specs[name].tets
            body = sapien.render.RenderBodyComponent()
            for faces, rgba, tet_idx, weights in self._visuals[name]:
                # Barycentric embedding: each visual vertex follows the tet it lies in.
                verts = np.einsum("vk,vkd->vd", weights, nodes[tets[tet_idx]]).astype(np.float32)
                body.attach(sapien.render.RenderShapeTriangleMesh(
                    vertices=verts,
                    triangles=faces.astype(np.uint32),
                    normals=_vertex_normals(verts, faces),
                    uvs=np.zeros((len(verts), 2), np.float32),
                    material=sapien.render.RenderMaterial(base_color=list(rgba), roughness=0.8),
                ))
            for old in [c for c in entity.components if isinstance(c, sapien.render.RenderBodyComponent)]:
                entity.remove_component(old)
            entity.add_component(body)

    # ------------------------------------------------------------------ tactile
    def contact_surface(self) -> tuple[np.ndarray, np.ndarray]:
        """World vertices and faces of every object's deformed FEM boundary: the surface the pads
        actually touch (the finer visual mesh is embedded and may sit slightly outside it). For
        rigid twins: the same boundary carried by the body's pose."""
        verts, faces, offset = [], [], 0
        for name in self._specs:
            nodes = self._nodes(name)
            verts.append(nodes)
            faces.append(self._boundary[name] + offset)
            offset += len(nodes)
        return np.concatenate(verts), np.concatenate(faces)

    def pad_pose(self, side: str) -> np.ndarray:
        """4x4 world pose of the ``side`` finger's gel surface (tactile pad frame, see tactile.sensor)."""
        other = {"left": "right", "right": "left"}[side]
        # Link poses as numpy matrices directly (ManiSkill's batched torch conversion costs ~0.15 ms
        # a link, most of a tactile frame's overhead).
        links = self.agent.robot.links_map
        centre = {}
        for s in (side, other):
            link = pose_wxyz_to_matrix(links[f"panda_{s}finger"].pose.raw_pose[0].cpu().numpy().astype(np.float64))
            centre[s] = link[:3, :3] @ np.asarray(C.FINGERTIP_OFFSET[s]) + link[:3, 3]
        hand = pose_wxyz_to_matrix(links["panda_hand"].pose.raw_pose[0].cpu().numpy().astype(np.float64))
        normal = centre[other] - centre[side]
        normal /= np.linalg.norm(normal)
        # Gel surface: the pad's inner face, moved out to where touching FEM nodes rest (their
        # contact radius): the object's surface reaches it exactly when it touches the pad. PhysX
        # bodies (rigid twins) rest on the face itself.
        radius = 0.0 if self._world is None else PC.PARTICLE_RADIUS
        face = centre[side] + normal * (C.FINGERTIP_HALF_EXTENTS[1] + radius)
        return finger_pad_frame(side, face, normal, hand[:3, 0].astype(np.float64))

    def pad_normal_force(self, side: str, pad_pose: np.ndarray | None = None) -> float:
        """Normal force (N) the objects press the ``side`` pad with: last tick's contact force on
        the finger along the pad normal (the part pulling the pad outwards, never negative).
        ``pad_pose``: that pad's pose if the caller has it already."""
        normal = (self.pad_pose(side) if pad_pose is None else pad_pose)[:3, 2]  # pad -> object
        link = f"panda_{side}finger"
        return max(0.0, -float(self._contact_wrenches((link,))[link][:3] @ normal))

    def tactile_contact_reference(self, side: str) -> np.ndarray:
        """Evaluator-only reference for the ``side`` sensor: (240, 320) bool, the objects' FEM
        surface at or past the pad within the gel's view, by exact polygon clipping
        (tactile.geometry.contact_polygons), which the rendered patch is checked against. A rigid
        twin does not reach past the pad (PhysX keeps it on the face); its reference is its
        surface at or past the gel sunk by the last frame's force-balanced depth (the geometric
        contact of a rigid indenter with the gel)."""
        nodes, faces = self.contact_surface()
        sensor = self._tactile[side]
        local = world_to_pad(nodes, self.pad_pose(side))
        if self._rigid:
            if sensor.frame is None:
                sensor.capture()
            local[:, 2] -= sensor.frame.sink
        return polygons_mask(contact_polygons(local, faces, sensor.renderer.view_half_extents))

    def pad_poses(self) -> dict[str, np.ndarray]:
        """Both fingers' pad poses: side -> 4x4 world pose."""
        return {side: self.pad_pose(side) for side in ("left", "right")}

    def tactile_frames(self) -> dict:
        """GelSight frames of both fingers for the current state (side -> TactileFrame), in any obs mode."""
        for sensor in self._tactile.values():
            sensor.capture()
        return {side: sensor.frame for side, sensor in self._tactile.items()}

    def tactile_background(self, side: str) -> np.ndarray:
        """The ``side`` finger's frame without contact (markers at rest): (240, 320, 3) uint8."""
        return self._tactile[side].renderer.background_frame

    # ------------------------------------------------------------------ state
    def get_state_dict(self):
        state = super().get_state_dict()  # rigid twins are ManiSkill actors: their state is in "actors"
        if self._world is not None:
            state["soft"] = torch.from_numpy(self._soft_state_vector()[None])
        return state

    def set_state_dict(self, state: dict, env_idx: torch.Tensor = None):
        if "soft" in state and self._world is None:
            raise ValueError("this state holds FEM soft-body values but the scene's objects are rigid twins (PhysX "
                             "bodies): it was recorded before the twins became rigid; regenerate the demonstrations")
        super().set_state_dict(self._changed_rigid_state(state), env_idx)
        if "soft" in state:
            # Batched (1, n) from get_state_dict, or one step (n,) as replay_trajectory hands it over.
            soft = np.asarray(to_numpy(state["soft"]))
            self._set_soft_state_vector(soft if soft.ndim == 1 else soft[0])

    def _changed_rigid_state(self, state: dict) -> dict:
        """``state`` without the actors and articulation roots that already hold exactly the stored
        values. PhysX keeps a body's centre-of-mass pose, so writing back a pose it just returned
        can move it by one float32 ulp; skipping unchanged bodies (the table, props, the robot's
        fixed base) makes restore-then-step reproduce a recorded trajectory bit for bit."""
        live = self.get_state_dict()
        out = {k: v for k, v in state.items() if k not in ("actors", "articulations")}
        for group in ("actors", "articulations"):
            if group not in state:
                continue
            out[group] = {}
            for name, value in state[group].items():
                value = torch.as_tensor(to_numpy(value)).reshape(1, -1)
                current = live[group].get(name)
                if current is not None and torch.equal(current.reshape(1, -1).to(value.dtype), value):
                    continue
                if group == "articulations" and current is not None and torch.equal(
                    current.reshape(1, -1)[:, :13].to(value.dtype), value[:, :13]
                ):
                    # Fixed base unchanged: restore the joints only.
                    art = self.scene.state_dict_registry.articulations[name]
                    qpos, qvel = value[0, 13:].numpy().reshape(2, -1)
                    art.set_qpos(qpos)
                    art.set_qvel(qvel)
                    continue
                out[group][name] = value
        return out

    def set_state(self, state, env_idx: torch.Tensor = None):
        # ManiSkill rebuilds only actors and articulations from a flat vector: the soft-body
        # state is the tail that get_state() appended.
        state = np.asarray(to_numpy(state))
        state = state[None] if state.ndim == 1 else state
        if self._world is None:
            super().set_state(torch.from_numpy(state), env_idx)
            return
        n_soft = self._soft_state_vector().size
        super().set_state(torch.from_numpy(state[:, :-n_soft]), env_idx)
        self._set_soft_state_vector(state[0, -n_soft:])

    def _soft_state_vector(self) -> np.ndarray:
        s = self._world.get_state()
        # While every body sleeps the world returns its frozen wrench every tick, which is then
        # also the coupling's last wrench: the wrenches below restore both.
        return np.concatenate([s["particle_q"].ravel(), s["particle_qd"].ravel(), s["collider_q"].ravel(),
                               self._coupling.wrenches.ravel(), s["sleep"]]).astype(np.float64)

    def _set_soft_state_vector(self, vec: np.ndarray):
        w = self._world
        n_p, n_b, n_c = w.model.particle_count, w.model.body_count, len(w.colliders)
        sizes = [n_p * 3, n_p * 3, n_b * 7, n_c * 6, 2 * len(w.soft_bodies)]
        if vec.size == sum(sizes[:-1]):  # recorded before soft bodies could sleep: awake
            vec = np.concatenate([vec, np.zeros(sizes[-1])])
        if vec.size != sum(sizes):
            raise ValueError(f"soft-body state has {vec.size} values, this scene needs {sum(sizes)}")
        q, qd, cq, wr, sleep = np.split(vec, np.cumsum(sizes)[:-1])
        wr = wr.reshape(n_c, 6).copy()
        w.set_state({"particle_q": q.reshape(-1, 3), "particle_qd": qd.reshape(-1, 3), "collider_q": cq.reshape(-1, 7),
                     "sleep": sleep, "sleep_wrench": wr})
        self._coupling.wrenches = wr
        self._update_render_meshes()

    def _place(self, name: str, pose: np.ndarray) -> None:
        p = np.asarray(pose, dtype=np.float64).copy()
        if name in self._rigid:
            self._rigid[name].set_pose(p)  # PhysX rests it on the support
            return
        # Spawn a hair above the support so the object settles onto it instead of starting in contact.
        p[2] += PC.PARTICLE_RADIUS + PC.SPAWN_CLEARANCE
        self._world.set_soft_body_pose(self._soft_index[name], p)
        self._coupling.teleport()

    def place_object(self, name: str, pose: np.ndarray, settle_time: float = 0.0) -> None:
        """Teleport an object, in its rest shape, to ``pose`` [p, q_wxyz] (bottom at p).

        For tests and scripted set-ups (success/drop predicates); x_0 is kept. With
        ``settle_time`` the FEM runs that long with the robot frozen (a rigid twin is placed at
        rest and has nothing to settle).
        """
        self._index(name)
        self._place(name, pose)
        if self._world is not None:
            for _ in range(int(round(settle_time * C.SIM_FREQ))):
                self._coupling.wrenches = self._world.step()
        self._update_render_meshes()

    @property
    def soft_world_stats(self) -> dict:
        """Newton ticks simulated and ticks skipped asleep since the env was built (benchmarks,
        tests); None in a scene of rigid twins (no Newton world)."""
        return None if self._world is None else dict(self._world.sleep_stats)

    # ------------------------------------------------------------------ evaluator-only
    @property
    def object_names(self) -> tuple[str, ...]:
        """Names of the soft objects of the scene, in simulation order ("object", or "left"/"right")."""
        return tuple(self._specs)

    def _index(self, name: str | None) -> int:
        names = self.object_names
        name = name or names[0]
        if name not in names:
            raise KeyError(f"no soft object '{name}' in this scene; objects: {list(names)}")
        return names.index(name)

    def rest_vertices(self, name: str | None = None) -> np.ndarray:
        """Rest shape of a soft object's tet mesh in its local frame (bottom at z = 0)."""
        return self._specs[self.object_names[self._index(name)]].vertices

    def _nodes(self, name: str) -> np.ndarray:
        if name in self._rigid:
            return self._rigid[name].nodes()
        return self._world.particle_q(self._soft_index[name])

    def soft_nodes(self, name: str | None = None) -> np.ndarray:
        """Current FEM node positions (world frame; a rigid twin's carried by its pose). Evaluator-only."""
        return self._nodes(self.object_names[self._index(name)])

    def soft_node_velocities(self, name: str | None = None) -> np.ndarray:
        """Current FEM node velocities (world frame; a rigid twin's from its body velocity). Evaluator-only."""
        name = self.object_names[self._index(name)]
        if name in self._rigid:
            return self._rigid[name].node_velocities()
        return self._world.particle_qd(self._soft_index[name])

    def settled_nodes(self, name: str | None = None) -> np.ndarray:
        """x_0: the nodes after the settle before the episode (world frame). Evaluator-only."""
        return self._x0[self.object_names[self._index(name)]]

    def deformation(self, name: str | None = None) -> float:
        """D_t of a soft object against its settled nodes x_0. Evaluator-only."""
        return deformation(self.soft_nodes(name), self.settled_nodes(name))

    def _contact_wrenches(self, names=FEEDBACK_LINKS) -> dict[str, np.ndarray]:
        """Last tick's wrench of the objects on the robot links ``names`` (fingers, hand; name ->
        [force, torque about the link frame origin], world frame): from the Newton coupling, or
        for rigid twins from PhysX's contact impulses (summed only for the links asked for)."""
        if self._coupling is not None:
            return {name: self._coupling.wrench(name) for name in names}
        contacts = self.scene.px.get_contacts()
        dt = 1.0 / C.SIM_FREQ
        links = self.agent.robot.links_map
        out = {}
        for name in names:
            entity = links[name]._objs[0].entity
            origin = np.asarray(entity.pose.p, np.float64)
            out[name] = sum((obj.contact_wrench(contacts, entity, dt, origin) for obj in self._rigid.values()),
                            np.zeros(6))
        return out

    def pad_wrenches(self) -> dict[str, np.ndarray]:
        """Last tick's contact wrench of the objects on each finger pad and on the hand:
        collider name -> [force (3) N, torque (3) N m about the link frame origin], world frame."""
        return {name: w.copy() for name, w in self._contact_wrenches().items()}

    def pad_forces(self) -> dict[str, float]:
        """Magnitude (N) of the contact force on each finger pad: side -> force."""
        w = self._contact_wrenches(("panda_leftfinger", "panda_rightfinger"))
        return {side: float(np.linalg.norm(w[f"panda_{side}finger"][:3])) for side in ("left", "right")}

    def object_material(self, name: str | None = None) -> dict[str, float | None]:
        """Live Young's modulus (Pa; None for a rigid twin) and mass (kg) of an object, after any
        OOD rescaling. Evaluator-only."""
        name = self.object_names[self._index(name)]
        if name in self._rigid:
            return {"youngs_modulus": None, "mass": self._rigid[name].mass}
        i = self._soft_index[name]
        h = self._world.soft_bodies[i]
        masses = self._world.model.particle_mass.numpy()[h.particle_start:h.particle_start + h.particle_count]
        return {"youngs_modulus": h.material.youngs_modulus * self._world.material_scale["youngs_modulus"],
                "mass": float(masses.sum())}

    def evaluator_state(self) -> dict:
        """Everything the evaluator may read and a policy must not: nodes, poses, D_t, materials."""
        out = {}
        for name in self.object_names:
            nodes = self.soft_nodes(name)
            x0 = self.settled_nodes(name)
            out[name] = {"nodes": nodes, "x0": x0, "centroid": nodes.mean(axis=0),
                         "deformation": deformation(nodes, x0), **self.object_material(name)}
        out["pad_wrenches"] = self.pad_wrenches()
        return out

    @property
    def gripper_width(self) -> float:
        """Jaw gap between the two fingertip pads (m)."""
        q = self.agent.robot.get_qpos()[0, -2:].cpu().numpy()
        return float(q.sum())


def _vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    return (n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)).astype(np.float32)


_HAND_HULL = None


def _hand_collision_hull():
    """Convex hull of the Panda hand's collision mesh (from the ManiSkill wheel), hand frame."""
    global _HAND_HULL
    if _HAND_HULL is None:
        import trimesh
        from mani_skill import PACKAGE_ASSET_DIR

        m = trimesh.load(f"{PACKAGE_ASSET_DIR}/robots/panda/franka_description/meshes/collision/hand.stl", force="mesh")
        hull = m.convex_hull
        _HAND_HULL = (np.asarray(hull.vertices), np.asarray(hull.faces))
    return _HAND_HULL
