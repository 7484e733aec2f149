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
  convex parts, mass, friction and colour; a scene of twins builds no Newton world at all. Both
  kinds sit behind one interface chosen when the scene loads (:mod:`.objects`), and the fingers'
  pads, inertia and colliders live in :mod:`.fingers`;
- a GelSight Mini on each finger, a ManiSkill sensor configured like the cameras
  (:attr:`SoftBodyEnv._default_tactile_configs`), observed in ``+tactile`` obs modes;
- blow-up detection (NaN, exploding velocities) after every control step; collapsed tets are
  counted for the evaluator (``collapsed_tets``), not raised.

Evaluator-only state (FEM nodes, object poses, deformation, material parameters) is exposed
through cheap public accessors (:meth:`soft_nodes`, :meth:`settled_nodes`, :meth:`pad_forces`, ...)
and :meth:`SoftBodyEnv.evaluator_state`, never through observations.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import sapien
import torch
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.envs.utils.observations import sensor_data_to_pointcloud
from mani_skill.sensors.camera import Camera, CameraConfig
from mani_skill.utils import sapien_utils
from mani_skill.utils.common import to_numpy
from mani_skill.utils.structs.types import SimConfig

from ..contracts.observations import SIDES, ObsMode
from ..physics.deformation import deformation
from ..tactile.gelsight import GelSight, GelSightConfig
from ..tactile.geometry import contact_polygons, polygons_mask
from ..tactile.sensor import world_to_pad
from . import constants as C
from . import fingers
from ..physics.config import DEFAULT_PHYSICS
from ..tactile.config import DEFAULT_TACTILE
from .objects import ObjectSpec, PropCollider, SceneObjects, build_objects  # noqa: F401  (specs: the tasks' API)
from .robot import PandaSoftVT, validate_action  # noqa: F401  (PandaSoftVT: registers the agent)
from .suites import FACTOR_OPTIONS, PhysicalFactors, resolve_factors

# Reset options: the episode's physical factors, and ManiSkill's own.
RESET_OPTIONS = frozenset({"ood", *FACTOR_OPTIONS, "reconfigure", "env_idx", "reset_to_env_states"})
# Resets between scene rebuilds: 1, every episode starts in a scene built for it (see __init__).
RECONFIGURATION_FREQ = 1


class SoftBodyEnv(BaseEnv):
    """ManiSkill env with Newton FEM soft bodies. CPU simulation, one env per process."""

    SUPPORTED_ROBOTS = ["panda_softvt"]
    # ManiSkill's: every camera texture and its combinations, point clouds and raw sensor data, each
    # also with "+tactile" (mani_skill_softvt.contracts.observations.ObsMode); the first is the default.
    SUPPORTED_OBS_MODES = ("state", "state_dict", "none", "sensor_data", "any_textures", "pointcloud")
    agent: PandaSoftVT

    def __init__(self, *args, robot_uids="panda_softvt", obs_mode: str | None = None, soft_sleep: bool = True,
                 physics: dict | None = None, tactile: dict | None = None, **kwargs):
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
        # Every reset rebuilds the scene (ManiSkill's reconfiguration; about 0.9 s). PhysX keeps
        # contact state across a plain reset that changes how a later contact rounds, so an
        # episode would depend on what ran before it in the same env (docs/limitations.md).
        # reconfiguration_freq=0 trades that for speed.
        kwargs.setdefault("reconfiguration_freq", RECONFIGURATION_FREQ)
        self.objects: SceneObjects | None = None  # the scene's objects (soft or rigid twins), built with it
        self._x0: dict[str, np.ndarray] = {}
        self._tactile: dict[str, GelSight] = {}  # side -> sensor, created with the scene's sensors
        self._skip_cameras = False  # set for one step by skip_cameras_next_step()
        self.settle_info: dict = {}
        # The physics settings (physics/config.py), the package's with ``physics``'s overrides: plain
        # values, so ManiSkill records them with the env's kwargs. What the FEM world, the objects and the
        # lockstep rate read; nothing patches module constants.
        self.physics = DEFAULT_PHYSICS.with_overrides(physics)
        # The GelSights' settings (tactile/config.py), overridden the same way: ``tactile={"gel_modulus": 1e6}``.
        self.tactile_config = DEFAULT_TACTILE.with_overrides(tactile)
        self.soft_sleep = bool(soft_sleep)  # resting soft bodies that nothing moving nears skip the FEM
        self.factors = PhysicalFactors()
        self._lights, self._ambient = [], None  # the scene's lights at nominal intensity (set when loaded)
        self.obs_mode_spec = ObsMode.parse(obs_mode)  # ValueError naming a mode that is not one
        self.tactile_enabled = self.obs_mode_spec.tactile
        super().__init__(*args, robot_uids=robot_uids, obs_mode=self.obs_mode_spec.camera, **kwargs)
        # ManiSkill parsed the camera part ("rgbd"); the public name keeps "+tactile".
        self._obs_mode = self.obs_mode_spec.name

    # ------------------------------------------------------------------ config
    @property
    def _default_sim_config(self):
        # Lockstep rate: SAPIEN and Newton both at SIM_FREQ (see physics.coupling).
        return SimConfig(sim_freq=self.physics.sim_freq, control_freq=C.CONTROL_FREQ)

    @property
    def _default_sensor_configs(self):
        # Third-person view of the workspace at the policy resolution.
        pose = sapien_utils.look_at(eye=[0.35, 0.0, 0.45], target=[-0.1, 0.0, 0.05])
        return [CameraConfig("base_camera", pose, C.CAMERA_SIZE, C.CAMERA_SIZE, np.pi / 2, 0.01, 100,
                             shader_pack=self.obs_mode_spec.shader_pack)]

    @property
    def _default_human_render_camera_configs(self):
        pose = sapien_utils.look_at(eye=[0.28, 0.28, 0.25], target=[0.0, 0.0, 0.06])
        return CameraConfig("render_camera", pose, 384, 288, 1.0, 0.01, 100)

    @property
    def _default_tactile_configs(self) -> list[GelSightConfig]:
        """A GelSight Mini on each finger (configured like the cameras, built in the sensor setup)."""
        return [GelSightConfig(f"tactile_{side}", side=side, pad_half_extents=C.GEL_PAD_HALF_EXTENTS,
                               tactile=self.tactile_config) for side in SIDES]

    def _setup_sensors(self, options: dict):
        super()._setup_sensors(options)  # ManiSkill builds the cameras only
        self._tactile = {cfg.side: GelSight(cfg, self.contact_surface, lambda side=cfg.side: self.pad_pose(side),
                                            lambda pose, side=cfg.side: self.pad_normal_force(side, pose),
                                            deformable=self.objects.deformable)
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
        if self._skip_cameras:
            # The GelSights still capture: their renderer remembers the contact onset that marker
            # shear is measured from, so a frame skipped would change the frames after it.
            for sensor in self._tactile.values() if self.tactile_enabled else ():
                sensor.capture()
            return {}
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

    def get_obs(self, info: dict | None = None, unflattened: bool = False):
        # ManiSkill's get_obs, for a mode name that may end in "+tactile": raw textures in sensor_data
        # modes, and the cameras' point cloud whenever the mode names one ("pointcloud+tactile",
        # "rgb+pointcloud"), from the cameras only (the GelSights are sensors without pixels in space).
        mode = self.obs_mode_spec
        if not mode.images:
            return super().get_obs(info, unflattened)
        obs = self._get_obs_with_sensor_data(self.get_info() if info is None else info,
                                             apply_texture_transforms=not mode.raw)
        if mode.pointcloud and obs["sensor_data"]:
            cameras = {uid: s for uid, s in self._sensors.items() if isinstance(s, Camera)}
            obs = sensor_data_to_pointcloud(obs, cameras)
        return obs if unflattened else self._flatten_raw_obs(obs)

    @cached_property
    def segmentation_id_map(self):
        """ManiSkill's map of segmentation ids to actors and links, with each soft object's drawn
        surface (one id per object, stable over the episode, named as its rigid twin is:
        ``object``, ``left``, ``right``). ManiSkill forgets it at each reconfiguration."""
        return {**BaseEnv.segmentation_id_map.func(self), **self.objects.segmentation_actors()}

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
        self._props = self._load_props(options)
        self.objects = build_objects(specs, self.scene, soft_sleep=self.soft_sleep, physics=self.physics)

    def _after_reconfigure(self, options):
        super()._after_reconfigure(options)
        fingers.set_finger_inertia(self.agent.robot)
        self.objects.connect(self.agent.robot, self.table, self._props)
        # The new scene is nominal; a reset to given env states skips _initialize_episode, so its
        # factors take effect here (applying them again there changes nothing: scales are absolute).
        self.apply_factors(resolve_factors(options))

    def _clear(self):
        # Let go of the old scene before ManiSkill collects it, so one scene is alive at a time.
        self.objects, self._props, self._tactile, self._lights, self._ambient = None, [], {}, [], None
        super()._clear()

    # ------------------------------------------------------------------ episode
    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        factors = resolve_factors(options)
        with torch.device(self.device):
            poses = self._initialize_task(env_idx, options)
        missing = set(self.objects.specs) - set(poses)
        if missing:
            raise RuntimeError(f"_initialize_task did not place soft objects {sorted(missing)}")
        self.apply_factors(factors)
        for name in self.objects.specs:
            self.objects.place(name, poses[name])
        self.settle()
        self.objects.update_render()
        for sensor in self._tactile.values():
            sensor.reset()

    def apply_factors(self, factors: PhysicalFactors) -> None:
        """The one place where an episode's physical factors take effect: Young's modulus and mass
        of every soft body (rescaled in place, no kernel rebuilt) and the light intensity."""
        self.objects.scale(youngs_modulus=factors.youngs_modulus_scale, mass=factors.mass_scale)
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
        # Settling is not part of the episode's physics: each back end drains kinetic energy so
        # that neutrally stable shapes (the ball) stop rocking instead of ringing for seconds.
        self.settle_info = self.objects.settle(speed, max_time, self.agent.robot)
        self._x0 = {name: self.objects.nodes(name) for name in self.objects.specs}
        return self.settle_info

    # ------------------------------------------------------------------ stepping
    def step(self, action):
        try:
            return super().step(self.validate_action(action))
        finally:
            self._skip_cameras = False

    def skip_cameras_next_step(self) -> None:
        """Render no camera for the next step: its observation's ``sensor_data`` is empty, every
        other entry (the GelSights' too) is as always. For an evaluator whose policy will not read
        those images (``Policy.needs_next_images``); rendering never changes the scene, so the
        episode is the same bit for bit."""
        self._skip_cameras = True

    def reset(self, seed=None, options=None):
        self._skip_cameras = False
        unknown = sorted(set(options or {}) - RESET_OPTIONS)
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; SoftVT envs take {sorted(RESET_OPTIONS)}")
        resolve_factors(options or {})  # a bad factor fails here, before the scene is rebuilt
        given = (options or {}).get("reset_to_env_states", {})
        if "obs" in given and self._last_obs is not None and "sensor_data" in self._last_obs \
                and not self._last_obs["sensor_data"]:
            # ManiSkill writes a given reset obs into the last step's structure, which a skipped
            # step left without cameras: observe afresh instead.
            options = {**options, "reset_to_env_states": {k: v for k, v in given.items() if k != "obs"}}
        return super().reset(seed=seed, options=options)

    def validate_action(self, action):
        """:func:`~mani_skill_softvt.tasks.robot.validate_action` against this env's action space."""
        return validate_action(action, self.single_action_space.shape, self.control_mode)

    def _before_simulation_step(self):
        self.objects.before_sim_step()

    def _after_simulation_step(self):
        self.objects.after_sim_step()

    def _after_control_step(self):
        self.objects.after_control_step()

    # ------------------------------------------------------------------ tactile
    def contact_surface(self) -> tuple[np.ndarray, np.ndarray]:
        """World vertices and faces of the surface the pads touch: every object's deformed FEM
        boundary, or a rigid twin's hulls as PhysX collides them (``SceneObjects.contact_surface``)."""
        return self.objects.contact_surface()

    def pad_pose(self, side: str) -> np.ndarray:
        """4x4 world pose of the ``side`` finger's gel surface (tactile pad frame, see tactile.sensor)."""
        return fingers.pad_pose(self.agent.robot, side, self.objects.contact_radius)

    def pad_normal_force(self, side: str, pad_pose: np.ndarray | None = None) -> float:
        """Normal force (N) the objects press the ``side`` pad with: last tick's contact force on
        the finger along the pad normal (the part pulling the pad outwards, never negative).
        ``pad_pose``: that pad's pose if the caller has it already."""
        normal = (self.pad_pose(side) if pad_pose is None else pad_pose)[:3, 2]  # pad -> object
        link = fingers.FINGER_LINKS[side]
        return max(0.0, -float(self.objects.contact_wrenches((link,))[link][:3] @ normal))

    def tactile_contact_reference(self, side: str) -> np.ndarray:
        """Evaluator-only reference for the ``side`` sensor: (240, 320) bool, the objects' contact
        surface (:meth:`contact_surface`) at or past the pad within the gel's view, by exact polygon clipping
        (tactile.geometry.contact_polygons), which the rendered patch is checked against. A rigid
        twin barely reaches past the pad (PhysX keeps it on the face, up to its contact slop); its
        reference is its surface at or past the gel sunk by the last frame's force-balanced depth
        (the geometric contact of a rigid indenter with the gel)."""
        nodes, faces = self.contact_surface()
        sensor = self._tactile[side]
        local = world_to_pad(nodes, self.pad_pose(side))
        if not sensor.deformable:
            if sensor.frame is None:
                sensor.capture()
            local[:, 2] -= sensor.frame.sink
        return polygons_mask(contact_polygons(local, faces, sensor.renderer.view_half_extents))

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
        state.update(self.objects.state_dict())  # the FEM state, if any
        return state

    def set_state_dict(self, state: dict, env_idx: torch.Tensor = None):
        self.objects.check_state_dict(state)  # e.g. FEM values in a scene of rigid twins
        super().set_state_dict(self._changed_rigid_state(state), env_idx)
        self.objects.load_state_dict(state)

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
        n = self.objects.state_size
        super().set_state(torch.from_numpy(state[:, :state.shape[1] - n]), env_idx)
        if n:
            self.objects.set_state_vector(state[0, -n:])

    def place_object(self, name: str, pose: np.ndarray, settle_time: float = 0.0) -> None:
        """Teleport an object, in its rest shape, to ``pose`` [p, q_wxyz] (bottom at p).

        For tests and scripted set-ups (success/drop predicates); x_0 is kept. With
        ``settle_time`` the FEM runs that long with the robot frozen (a rigid twin is placed at
        rest and has nothing to settle).
        """
        name = self.object_names[self._index(name)]
        self.objects.place(name, pose)
        self.objects.run_free(int(round(settle_time * self.physics.sim_freq)))
        self.objects.update_render()

    @property
    def soft_world_stats(self) -> dict:
        """Newton ticks simulated and ticks skipped asleep since the last reset (which builds the
        scene) (benchmarks, tests); None in a scene of rigid twins (no Newton world)."""
        return self.objects.stats

    # ------------------------------------------------------------------ evaluator-only
    @property
    def object_names(self) -> tuple[str, ...]:
        """Names of the soft objects of the scene, in simulation order ("object", or "left"/"right")."""
        return tuple(self.objects.specs)

    def _index(self, name: str | None) -> int:
        names = self.object_names
        name = name or names[0]
        if name not in names:
            raise KeyError(f"no soft object '{name}' in this scene; objects: {list(names)}")
        return names.index(name)

    def rest_vertices(self, name: str | None = None) -> np.ndarray:
        """Rest shape of a soft object's tet mesh in its local frame (bottom at z = 0)."""
        return self.objects.specs[self.object_names[self._index(name)]].vertices

    def soft_nodes(self, name: str | None = None) -> np.ndarray:
        """Current FEM node positions (world frame; a rigid twin's carried by its pose). Evaluator-only."""
        return self.objects.nodes(self.object_names[self._index(name)])

    def soft_node_velocities(self, name: str | None = None) -> np.ndarray:
        """Current FEM node velocities (world frame; a rigid twin's from its body velocity). Evaluator-only."""
        return self.objects.node_velocities(self.object_names[self._index(name)])

    def settled_nodes(self, name: str | None = None) -> np.ndarray:
        """x_0: the nodes after the settle before the episode (world frame). Evaluator-only."""
        return self._x0[self.object_names[self._index(name)]]

    def drawn_surface(self, name: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Evaluator-only: world vertices and triangles of ``name`` as the cameras draw it now (a soft
        object's visual meshes carried by its FEM nodes; a twin's at its pose)."""
        return self.objects.drawn_surface(self.object_names[self._index(name)])

    def deformation(self, name: str | None = None) -> float:
        """D_t of a soft object against its settled nodes x_0. Evaluator-only."""
        return deformation(self.soft_nodes(name), self.settled_nodes(name))

    def collapsed_tets(self) -> int:
        """Tets of the scene's soft objects now collapsed or inverted (volume <= 2 % of rest; 0 for
        rigid twins). A concentrated load does it, e.g. a fingertip edge pressing one surface node
        (docs/limitations.md); the FEM recovers, and the evaluator scores it. Evaluator-only."""
        return sum(self.objects.collapsed_tets(name) for name in self.object_names)

    def pad_wrenches(self) -> dict[str, np.ndarray]:
        """Last tick's contact wrench of the objects on each finger pad and on the hand:
        collider name -> [force (3) N, torque (3) N m about the link frame origin], world frame."""
        return {name: w.copy() for name, w in self.objects.contact_wrenches(fingers.FEEDBACK_LINKS).items()}

    def pad_forces(self) -> dict[str, float]:
        """Magnitude (N) of the contact force on each finger pad: side -> force."""
        w = self.objects.contact_wrenches(tuple(fingers.FINGER_LINKS.values()))
        return {side: float(np.linalg.norm(w[link][:3])) for side, link in fingers.FINGER_LINKS.items()}

    def object_material(self, name: str | None = None) -> dict[str, float | None]:
        """Live Young's modulus (Pa; None for a rigid twin) and mass (kg) of an object, after any
        OOD rescaling. Evaluator-only."""
        return self.objects.material(self.object_names[self._index(name)])

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
        return fingers.gripper_width(self.agent.robot)

