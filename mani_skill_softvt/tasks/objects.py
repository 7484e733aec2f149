"""The scene's manipulated objects behind one small interface, chosen once when the scene loads.

A scene's objects are all FEM soft bodies (:class:`FEMObjects`: a Newton world stepped in
lockstep with SAPIEN, :mod:`mani_skill_softvt.physics.coupling`) or all rigid twins
(:class:`RigidTwins`: PhysX bodies, :mod:`mani_skill_softvt.physics.rigid`). Both answer the same
questions (:class:`SceneObjects`): place an object, settle the scene, nodes and node velocities
(a twin's nodes are its soft asset's carried by its pose), the contact wrenches on the robot's
links, the live material, the episode's physical factors, and the part of the env state the
robot's articulation does not hold. The env (:mod:`.soft_body_env`) calls only this interface.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sapien
import torch
from mani_skill.utils.common import to_numpy
from mani_skill.utils.structs.actor import Actor

from ..assets.cards import read_obj
from ..assets.materials import SoftMaterial
from ..assets.tetmesh import embed_points, join_meshes, surface_of_tets, vertex_normals
from ..physics import constants as PC
from ..physics.coupling import MirroredBody, SapienNewtonCoupling
from ..physics.config import DEFAULT_PHYSICS, PhysicsConfig
from ..physics.errors import SimulationInstabilityError
from ..physics.fem import SoftBodyWorld
from ..physics.rigid import RigidObject, rigid_nodes
from . import constants as C
from . import fingers


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


class SceneObjects:
    """What the env asks of its objects, whichever simulator holds them.

    Built in the env's ``_load_scene`` (after the props) and connected to the robot, the table
    and the props in ``_after_reconfigure``; the same names in simulation order as ``specs``.
    """

    deformable: bool  # FEM surfaces (the gel's pressure indentation) or rigid bodies (force balance)
    contact_radius: float  # m: how far from a collider face the objects' touching surface rests

    def __init__(self, specs: list[ObjectSpec], scene, physics: PhysicsConfig = DEFAULT_PHYSICS):
        self.specs = {s.name: s for s in specs}
        self.scene = scene
        self.physics = physics  # the env's: its lockstep rate, and for FEM bodies the solver and contact

    def connect(self, robot, table, props: list[PropCollider]) -> None:
        """The robot, the table and the props are in the scene: couple the objects to them."""

    # --- episode
    def scale(self, youngs_modulus: float, mass: float) -> None:
        """Rescale every object's Young's modulus (a rigid body has none) and mass (x nominal)."""
        raise NotImplementedError

    def place(self, name: str, pose: np.ndarray) -> None:
        """Teleport ``name``, at rest in its rest shape, to [p, q_wxyz] (bottom at p)."""
        raise NotImplementedError

    def settle(self, speed: float, max_time: float, robot) -> dict:
        """Let the objects come to rest on their supports, the robot held still; returns
        ``{"ticks", "max_node_speed", "settled"}``."""
        raise NotImplementedError

    def run_free(self, ticks: int) -> None:
        """Let the objects move for ``ticks`` physics ticks with the robot frozen (scripted set-ups)."""

    # --- stepping
    def before_sim_step(self) -> None:
        pass

    def after_sim_step(self) -> None:
        pass

    def after_control_step(self) -> None:
        """Check the simulation's health and show the objects' current shape to the cameras."""

    def update_render(self) -> None:
        pass

    def segmentation_actors(self) -> dict:
        """Segmentation id -> ManiSkill Actor of what the cameras see of each object that is not
        already one of the scene's actors (ManiSkill's ``segmentation_id_map`` holds those)."""
        return {}

    def drawn_surface(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World vertices and triangles of ``name`` as the cameras draw it now (evaluator-only)."""
        raise NotImplementedError

    # --- reading
    def nodes(self, name: str) -> np.ndarray:
        raise NotImplementedError

    def node_velocities(self, name: str) -> np.ndarray:
        raise NotImplementedError

    def collapsed_tets(self, name: str) -> int:
        """Tets of ``name`` collapsed or inverted now (none in a rigid twin's evaluation mesh)."""
        return 0

    def contact_wrenches(self, links: tuple[str, ...]) -> dict[str, np.ndarray]:
        """Last tick's wrench of the objects on the robot links ``links``: name -> [force,
        torque about the link frame origin], world frame."""
        raise NotImplementedError

    def material(self, name: str) -> dict[str, float | None]:
        raise NotImplementedError

    def contact_surface(self) -> tuple[np.ndarray, np.ndarray]:
        """World vertices and triangles of every object's surface the gel pads touch, as one mesh."""
        raise NotImplementedError

    @property
    def stats(self) -> dict | None:
        """Soft-body ticks simulated and skipped asleep (None without a Newton world)."""
        return None

    # --- state beyond ManiSkill's actors and articulations
    def state_dict(self) -> dict:
        return {}

    def check_state_dict(self, state: dict) -> None:
        """Refuse, before anything is restored, a state these objects cannot hold."""

    def load_state_dict(self, state: dict) -> None:
        """Restore what :meth:`state_dict` returned (batched (1, n) or one replayed step (n,))."""

    @property
    def state_size(self) -> int:
        """Length of the tail :meth:`state_dict` adds to ManiSkill's flat state vector."""
        return 0

    def set_state_vector(self, vec: np.ndarray) -> None:
        pass


def build_objects(specs: list[ObjectSpec], scene, soft_sleep: bool = True,
                  physics: PhysicsConfig = DEFAULT_PHYSICS) -> SceneObjects:
    """The scene's objects under ``physics``: all soft (:class:`FEMObjects`) or all rigid twins (:class:`RigidTwins`)."""
    if len({s.rigid for s in specs}) > 1:
        # One tactile model per frame (gel over an FEM surface, or force balance on a rigid one).
        raise ValueError(f"a scene's objects must be all soft or all rigid twins, got {[(s.name, s.rigid) for s in specs]}")
    return RigidTwins(specs, scene, physics) if specs[0].rigid else FEMObjects(specs, scene, soft_sleep, physics)


# The env-state key of a twin scene's last-tick contact wrenches (RigidTwins below).
TWIN_CONTACT_STATE = "contact_wrenches"


class RigidTwins(SceneObjects):
    """Rigid twins: PhysX does everything, and contact wrenches come from its contact impulses.

    Those impulses are the last tick's, which a restored state does not have (PhysX computes
    contacts only when it steps): the wrenches on the robot's feedback links are part of the
    twins' state (``contact_wrenches``), as the coupling's wrenches are of the FEM state, and a
    restored state's wrenches stand until the next tick. Without them a state restored to render
    its observations would show a pinched twin to the gel with no force: a blank tactile frame."""

    deformable = False
    contact_radius = 0.0
    STATE_KEY = TWIN_CONTACT_STATE

    def __init__(self, specs: list[ObjectSpec], scene, physics: PhysicsConfig = DEFAULT_PHYSICS):
        super().__init__(specs, scene, physics)
        self.bodies = {spec.name: self._build(spec, k) for k, spec in enumerate(specs)}
        self.robot = None
        self._restored_wrenches: np.ndarray | None = None  # (len(FEEDBACK_LINKS), 6), until the next tick

    def _build(self, spec: ObjectSpec, k: int) -> RigidObject:
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

    def connect(self, robot, table, props) -> None:
        self.robot = robot

    def drawn_surface(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        spec, pose = self.specs[name], self.bodies[name].pose7()
        parts = [read_obj(path) for path, _ in spec.visual_files]
        v, f = join_meshes([(rigid_nodes(rigid_nodes(v, np.asarray(spec.rest_pose)), pose), f) for v, f in parts])
        return v, f

    def scale(self, youngs_modulus: float, mass: float) -> None:
        for obj in self.bodies.values():
            obj.scale_mass(mass)  # a rigid body has no modulus to scale

    def place(self, name: str, pose: np.ndarray) -> None:
        self._restored_wrenches = None
        self.bodies[name].set_pose(pose)  # PhysX rests it on the support

    def settle(self, speed: float, max_time: float, robot) -> dict:
        # Settle in PhysX too (a faceted ball placed on a vertex would roll away otherwise),
        # with the robot held at its reset joint state.
        qpos, qvel = robot.get_qpos().clone(), robot.get_qvel().clone()
        freq = self.physics.sim_freq
        ticks, max_ticks, min_ticks = 0, int(max_time * freq), freq // 10
        while True:
            self.before_sim_step()
            self.scene.step()
            robot.set_qpos(qpos)
            robot.set_qvel(qvel)
            for obj in self.bodies.values():
                obj.damp_velocities(C.SETTLE_VELOCITY_DAMPING)
            v = max(obj.speed() for obj in self.bodies.values())
            ticks += 1
            if (ticks >= min_ticks and v < speed) or ticks >= max_ticks:
                break
        return {"ticks": ticks, "max_node_speed": v, "settled": v < speed}

    def nodes(self, name: str) -> np.ndarray:
        return self.bodies[name].nodes()

    def node_velocities(self, name: str) -> np.ndarray:
        return self.bodies[name].node_velocities()

    def before_sim_step(self) -> None:
        self._restored_wrenches = None  # the tick about to run computes its own contacts

    def contact_wrenches(self, links: tuple[str, ...]) -> dict[str, np.ndarray]:
        if self._restored_wrenches is not None:
            restored = dict(zip(fingers.FEEDBACK_LINKS, self._restored_wrenches))
            return {name: restored[name].copy() for name in links}
        contacts = self.scene.px.get_contacts()
        dt = 1.0 / self.physics.sim_freq
        links_map = self.robot.links_map
        out = {}
        for name in links:
            entity = links_map[name]._objs[0].entity
            origin = np.asarray(entity.pose.p, np.float64)
            out[name] = sum((obj.contact_wrench(contacts, entity, dt, origin) for obj in self.bodies.values()),
                            np.zeros(6))
        return out

    def material(self, name: str) -> dict[str, float | None]:
        return {"youngs_modulus": None, "mass": self.bodies[name].mass}

    def contact_surface(self) -> tuple[np.ndarray, np.ndarray]:
        """The hulls PhysX collides (not the tet boundary, which can sit outside them)."""
        return join_meshes([body.surface() for body in self.bodies.values()])

    def state_dict(self) -> dict:
        return {self.STATE_KEY: torch.from_numpy(self._state_vector()[None])}

    def load_state_dict(self, state: dict) -> None:
        # A state recorded before the wrenches were kept leaves PhysX's own (stale) contacts:
        # its poses restore exactly, its touch cannot (render refuses such a trajectory).
        if self.STATE_KEY in state:
            self.set_state_vector(np.asarray(to_numpy(state[self.STATE_KEY]), np.float64).reshape(-1))

    @property
    def state_size(self) -> int:
        return 6 * len(fingers.FEEDBACK_LINKS)

    def _state_vector(self) -> np.ndarray:
        wrenches = self.contact_wrenches(fingers.FEEDBACK_LINKS)
        return np.concatenate([wrenches[name] for name in fingers.FEEDBACK_LINKS]).astype(np.float64)

    def set_state_vector(self, vec: np.ndarray) -> None:
        if vec.size != self.state_size:
            raise ValueError(f"rigid twins' contact state has {vec.size} values, this scene needs {self.state_size}")
        self._restored_wrenches = vec.reshape(len(fingers.FEEDBACK_LINKS), 6).copy()

    def check_state_dict(self, state: dict) -> None:
        if "soft" in state:
            raise ValueError("this state holds FEM soft-body values but the scene's objects are rigid twins (PhysX "
                             "bodies): it was recorded before the twins became rigid; regenerate the demonstrations")


class FEMObjects(SceneObjects):
    """FEM soft bodies in a Newton world, stepped in lockstep with SAPIEN; drawn deformed."""

    deformable = True
    def __init__(self, specs: list[ObjectSpec], scene, sleeping: bool = True,
                 physics: PhysicsConfig = DEFAULT_PHYSICS):
        super().__init__(specs, scene, physics)
        self.contact_radius = physics.particle_radius
        self.sleeping = sleeping
        self.boundary = {n: surface_of_tets(s.tets) for n, s in self.specs.items()}  # what the gel touches
        self.index = {s.name: i for i, s in enumerate(specs)}  # Newton body index
        self.world: SoftBodyWorld | None = None
        self.coupling: SapienNewtonCoupling | None = None
        sub_scene = scene.sub_scenes[0]
        self.render_entities = {}
        for spec in specs:
            entity = sapien.Entity()
            entity.set_name(f"soft/{spec.name}")
            sub_scene.add_entity(entity)
            self.render_entities[spec.name] = entity
        # What is drawn for each object: (faces, rgba, embedding tet index, weights).
        self.visuals = {}
        for n, spec in self.specs.items():
            parts = spec.visual_parts or [(spec.vertices, surface_of_tets(spec.tets), spec.color)]
            self.visuals[n] = [(f, rgba, *embed_points(v, spec.vertices, spec.tets)) for v, f, rgba in parts]

    def connect(self, robot, table, props) -> None:
        """The Newton world: one tet body per object, colliders mirrored from the finger pads, the
        hand, the table top and every prop that declares a collider."""
        soft = list(self.specs.values())
        substeps, iterations = self.physics.vbd_schedule(s.material.youngs_modulus for s in soft)
        world = SoftBodyWorld(substeps=substeps, iterations=iterations, sleeping=self.sleeping, physics=self.physics)
        for spec in soft:
            world.add_soft_body(spec.name, spec.vertices, spec.tets, spec.material, pose=np.array([0, 0, -1.0, 1, 0, 0, 0]))
        bodies = []
        robot_links = {link.name: link._objs[0] for link in robot.get_links()}
        for side, name in fingers.FINGER_LINKS.items():
            world.add_collider_box(name, C.FINGERTIP_HALF_EXTENTS, local_pose=fingers.fingertip_box_pose(side),
                                   friction=self.physics.finger_friction, movable=True)
            bodies.append(MirroredBody(name, robot_links[name], feedback=True))
        hand = fingers.HAND_LINK
        world.add_collider_convex(hand, [fingers.hand_collision_hull()], friction=self.physics.finger_friction,
                                  movable=True)
        bodies.append(MirroredBody(hand, robot_links[hand], feedback=True))
        he = C.TABLE_HALF_EXTENTS
        world.add_collider_box("table", he, local_pose=np.array([0, 0, -he[2], 1, 0, 0, 0]), friction=self.physics.table_friction)
        bodies.append(MirroredBody("table", table._bodies[0], feedback=False))
        for prop in props:
            if prop.boxes:
                world.add_collider_boxes(prop.name, prop.boxes, friction=prop.friction)
            else:
                world.add_collider_convex(prop.name, prop.convex_parts, friction=prop.friction)
            bodies.append(MirroredBody(prop.name, prop.component, feedback=False))
        world.finalize()
        self.world = world
        self.coupling = SapienNewtonCoupling(world, bodies)

    def scale(self, youngs_modulus: float, mass: float) -> None:
        self.world.scale_materials(youngs_modulus=youngs_modulus, mass=mass)  # in place, no kernel rebuilt

    def place(self, name: str, pose: np.ndarray) -> None:
        p = np.asarray(pose, dtype=np.float64).copy()
        # Spawn a hair above the support so the object settles onto it instead of starting in contact.
        p[2] += self.physics.particle_radius + PC.SPAWN_CLEARANCE
        self.world.set_soft_body_pose(self.index[name], p)
        self.coupling.teleport()

    def settle(self, speed: float, max_time: float, robot) -> dict:
        # Newton only: the robot is frozen because SAPIEN does not step.
        world = self.world
        freq = self.physics.sim_freq
        ticks, max_ticks, min_ticks = 0, int(max_time * freq), freq // 10
        while True:
            world.step()
            world.damp_velocities(C.SETTLE_VELOCITY_DAMPING)
            v = max(float(np.abs(world.particle_qd(i)).max()) for i in self.index.values())
            ticks += 1
            if (ticks >= min_ticks and v < speed) or ticks >= max_ticks:
                break
        world.check_health()
        collapsed = {name: world.collapsed_tets(i) for name, i in self.index.items()}
        if any(collapsed.values()):  # a scene defect (a spawn inside a prop), not a policy's doing
            raise SimulationInstabilityError(f"settling collapsed tets {collapsed} before the episode began")
        world.wake()  # the episode starts awake; it may fall asleep in its own first ticks
        self.coupling.wrenches[:] = 0.0
        world.time = 0.0
        return {"ticks": ticks, "max_node_speed": v, "settled": v < speed}

    def run_free(self, ticks: int) -> None:
        for _ in range(ticks):
            self.coupling.wrenches = self.world.step()

    def before_sim_step(self) -> None:
        self.coupling.before_sapien_step()

    def after_sim_step(self) -> None:
        self.coupling.after_sapien_step()

    def after_control_step(self) -> None:
        self.world.check_health()
        self.update_render()

    def _drawn_parts(self, name: str):
        """(vertices, faces, rgba) of each visual part of ``name`` at the current nodes."""
        nodes = self.world.particle_q(self.index[name])
        tets = self.specs[name].tets
        for faces, rgba, tet_idx, weights in self.visuals[name]:
            # Barycentric embedding: each visual vertex follows the tet it lies in.
            yield np.einsum("vk,vkd->vd", weights, nodes[tets[tet_idx]]).astype(np.float32), faces, rgba

    def drawn_surface(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        parts = list(self._drawn_parts(name))
        return join_meshes([(v, f) for v, f, _ in parts])

    def segmentation_actors(self) -> dict:
        # The drawn surface is a render body on an entity of its own (no PhysX body: the FEM moves
        # it); wrapped as a ManiSkill Actor so that the map's users find it as they find any actor.
        return {entity.per_scene_id: Actor.create_from_entities([entity], self.scene, torch.zeros(1, dtype=torch.int),
                                                                shared_name=name)
                for name, entity in self.render_entities.items()}

    def update_render(self) -> None:
        for name, entity in self.render_entities.items():
            body = sapien.render.RenderBodyComponent()
            for verts, faces, rgba in self._drawn_parts(name):
                body.attach(sapien.render.RenderShapeTriangleMesh(
                    vertices=verts,
                    triangles=faces.astype(np.uint32),
                    normals=vertex_normals(verts, faces),
                    uvs=np.zeros((len(verts), 2), np.float32),
                    material=sapien.render.RenderMaterial(base_color=list(rgba), roughness=0.8),
                ))
            for old in [c for c in entity.components if isinstance(c, sapien.render.RenderBodyComponent)]:
                entity.remove_component(old)
            entity.add_component(body)

    def nodes(self, name: str) -> np.ndarray:
        return self.world.particle_q(self.index[name])

    def node_velocities(self, name: str) -> np.ndarray:
        return self.world.particle_qd(self.index[name])

    def collapsed_tets(self, name: str) -> int:
        return self.world.collapsed_tets(self.index[name])

    def contact_wrenches(self, links: tuple[str, ...]) -> dict[str, np.ndarray]:
        return {name: self.coupling.wrench(name) for name in links}

    def contact_surface(self) -> tuple[np.ndarray, np.ndarray]:
        """The deformed FEM boundaries (the finer visual meshes are embedded and may sit slightly outside)."""
        return join_meshes([(self.nodes(name), self.boundary[name]) for name in self.specs])

    def material(self, name: str) -> dict[str, float | None]:
        h = self.world.soft_bodies[self.index[name]]
        masses = self.world.model.particle_mass.numpy()[h.particle_start:h.particle_start + h.particle_count]
        return {"youngs_modulus": h.material.youngs_modulus * self.world.material_scale["youngs_modulus"],
                "mass": float(masses.sum())}

    @property
    def stats(self) -> dict:
        return dict(self.world.sleep_stats)

    def state_dict(self) -> dict:
        return {"soft": torch.from_numpy(self._state_vector()[None])}

    def load_state_dict(self, state: dict) -> None:
        if "soft" in state:
            # Batched (1, n) from get_state_dict, or one step (n,) as replay_trajectory hands it over.
            soft = np.asarray(to_numpy(state["soft"]))
            self.set_state_vector(soft if soft.ndim == 1 else soft[0])

    @property
    def state_size(self) -> int:
        return self._state_vector().size

    def _state_vector(self) -> np.ndarray:
        s = self.world.get_state()
        # While every body sleeps the world returns its frozen wrench every tick, which is then
        # also the coupling's last wrench: the wrenches below restore both.
        return np.concatenate([s["particle_q"].ravel(), s["particle_qd"].ravel(), s["collider_q"].ravel(),
                               self.coupling.wrenches.ravel(), s["sleep"]]).astype(np.float64)

    def set_state_vector(self, vec: np.ndarray) -> None:
        w = self.world
        n_p, n_b, n_c = w.model.particle_count, w.model.body_count, len(w.colliders)
        sizes = [n_p * 3, n_p * 3, n_b * 7, n_c * 6, 2 * len(w.soft_bodies)]
        if vec.size != sum(sizes):
            before_sleep = " (recorded before soft bodies could sleep, without their sleep state: record " \
                "the demos again)" if vec.size == sum(sizes[:-1]) else ""
            raise ValueError(f"soft-body state has {vec.size} values, this scene needs {sum(sizes)}{before_sleep}")
        q, qd, cq, wr, sleep = np.split(vec, np.cumsum(sizes)[:-1])
        wr = wr.reshape(n_c, 6).copy()
        w.set_state({"particle_q": q.reshape(-1, 3), "particle_qd": qd.reshape(-1, 3), "collider_q": cq.reshape(-1, 7),
                     "sleep": sleep, "sleep_wrench": wr})
        self.coupling.wrenches = wr
        self.update_render()
