"""Volumetric FEM soft bodies in Newton (SolverVBD) with kinematic colliders.

``SoftBodyWorld`` owns one Newton model: the tetrahedral soft objects of a scene and the
rigid colliders (finger pads, hand, table top, containers) whose poses another simulator
(SAPIEN) dictates. Each :meth:`SoftBodyWorld.step` advances the soft bodies one time step
with the colliders moved to their new poses, and returns the contact wrench that the soft
bodies exert on every collider, so the caller can push it back into the rigid simulator.

Why this shape:
- Newton integrates only the particles (``integrate_with_external_rigid_solver=True``): the
  colliders' start-of-step poses go into the input state, end-of-step poses into the output
  state, and VBD uses both for contact and friction (velocity from the pose difference).
- The whole step (collision detection, VBD iterations, wrench reduction) is captured once as
  a Warp CPU graph and replayed, which removes most Python launch overhead.
- Material and mass are rescaled in place (OOD conditions) without recompiling kernels.

Units: SI. Poses: Newton order ``[p, q_xyzw]`` internally; callers use SAPIEN order and convert
through :mod:`mani_skill_softvt.physics.transforms`.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field

import numpy as np

from ..assets.materials import SoftMaterial  # noqa: F401  (the material type lives with the assets' materials)
from ..paths import WARP_CACHE_DIR
from . import constants as C
from .config import DEFAULT_PHYSICS, PhysicsConfig
from .errors import SimulationInstabilityError  # raised here, defined apart for its handlers
from .sleeping import SLEEP_TICKS, WAKE_MARGIN, box_corners, box_gap, is_quiet, local_bounds, world_boxes
from .transforms import angular_velocity_xyzw, pose_wxyz_to_matrix, sapien_pose_to_newton

os.environ.setdefault("WARP_CACHE_PATH", str(WARP_CACHE_DIR))

from ..provenance.numerics import configure_warp  # noqa: E402

wp = configure_warp()  # the kernels compile for the pinned target, not the host (numerics.py)
# Warp logs every kernel-module load and its init banner at INFO: commands print only their own output.
wp.config.log_level = wp.LOG_WARNING
wp.config.kernel_cache_dir = os.environ["WARP_CACHE_PATH"]

import newton  # noqa: E402


def _init_warp() -> None:
    """Initialise Warp once, without the one-line "Could not find or load the NVIDIA CUDA driver"
    that its native library writes to stderr on every machine without a GPU (we run on the CPU);
    a real failure still raises. Idempotent, like ``wp.init``."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def vbd_schedule(youngs_moduli, physics: PhysicsConfig = DEFAULT_PHYSICS) -> tuple[int, int]:
    """(Newton substeps per tick, VBD iterations per substep) for a world holding bodies of these
    moduli (Pa), under ``physics`` (:meth:`PhysicsConfig.vbd_schedule`)."""
    return physics.vbd_schedule(youngs_moduli)


def lame_parameters(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """(mu, lambda) Lame parameters of an isotropic material."""
    e, nu = youngs_modulus, poisson_ratio
    return e / (2.0 * (1.0 + nu)), e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def tet_volumes(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes of tetrahedra (positive for the orientation Newton expects)."""
    v = np.asarray(vertices, dtype=np.float64)
    a, b, c, d = (v[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def collapsed_count(vertices: np.ndarray, rest_vertices: np.ndarray, tets: np.ndarray,
                    ratio: float = C.MIN_TET_VOLUME_RATIO) -> int:
    """Tets whose signed volume is at most ``ratio`` times their rest volume (collapsed or inverted)."""
    return int((tet_volumes(vertices, tets) <= ratio * tet_volumes(rest_vertices, tets)).sum())


def lumped_node_masses(vertices: np.ndarray, tets: np.ndarray, density: float) -> np.ndarray:
    """Lumped FEM masses: each tet gives a quarter of density*volume to each of its nodes."""
    m = np.zeros(len(vertices))
    np.add.at(m, np.asarray(tets).reshape(-1), np.repeat(density * tet_volumes(vertices, tets) / 4.0, 4))
    return m


@dataclass
class SoftBodyHandle:
    """Where a soft body lives inside the Newton model."""

    name: str
    particle_start: int
    particle_count: int
    tet_start: int
    tet_count: int
    material: SoftMaterial
    rest_vertices: np.ndarray  # local frame (N, 3)
    tets: np.ndarray  # local indices (M, 4)


@dataclass
class ColliderHandle:
    name: str
    body: int
    shapes: list[int] = field(default_factory=list)
    movable: bool = False  # may push a soft body at any time (the robot): keeps it awake when near
    bound_points: list[np.ndarray] = field(default_factory=list)  # shape points in the collider frame


@wp.kernel
def _sum_soft_contact_wrenches(
    soft_contact_count: wp.array[wp.int32],
    soft_contact_shape: wp.array[wp.int32],
    soft_contact_particle: wp.array[wp.int32],
    particle_flags: wp.array[wp.int32],
    shape_body: wp.array[wp.int32],
    contact_f: wp.array[wp.spatial_vector],
    soft_row_offset: int,
    body_wrench: wp.array[wp.spatial_vector],
):
    # Serial on CPU, so the reduction order (and the result) is deterministic.
    tid = wp.tid()
    if tid >= soft_contact_count[0]:
        return
    shape = soft_contact_shape[tid]
    if shape < 0:
        return
    # A sleeping body's particles are inactive: VBD leaves their contacts unsolved.
    if (particle_flags[soft_contact_particle[tid]] & int(newton.ParticleFlags.ACTIVE)) == 0:
        return
    body = shape_body[shape]
    if body < 0:
        return
    wp.atomic_add(body_wrench, body, contact_f[soft_row_offset + tid])


@wp.kernel
def _interpolate_body_q(
    q_start: wp.array[wp.transform], q_end: wp.array[wp.transform], alpha: float, out: wp.array[wp.transform]
):
    # Colliders move linearly (position lerp, rotation slerp) across the substeps of one tick.
    i = wp.tid()
    a = q_start[i]
    b = q_end[i]
    p = wp.transform_get_translation(a) * (1.0 - alpha) + wp.transform_get_translation(b) * alpha
    out[i] = wp.transform(p, wp.quat_slerp(wp.transform_get_rotation(a), wp.transform_get_rotation(b), alpha))


class SoftBodyWorld:
    """A Newton model holding soft FEM bodies and kinematic colliders.

    Build: :meth:`add_soft_body`, :meth:`add_collider_box` / :meth:`add_collider_convex`, then
    :meth:`finalize`. Run: :meth:`set_collider_poses` then :meth:`step` every physics tick.
    """

    def __init__(
        self,
        dt: float | None = None,
        substeps: int | None = None,
        iterations: int | None = None,
        gravity: float = -9.81,
        contact_ke: float | None = None,
        contact_kd: float | None = None,
        particle_radius: float | None = None,
        contact_gap: float | None = None,
        use_graph: bool = True,
        device: str = "cpu",
        sleeping: bool = False,
        physics: PhysicsConfig = DEFAULT_PHYSICS,
    ):
        """The settings not given are ``physics``'s (its lockstep rate, VBD schedule for soft bodies,
        contact and friction smoothing)."""
        _init_warp()
        self.physics = physics
        pick = lambda given, default: default if given is None else given  # noqa: E731
        self.dt = float(pick(dt, 1.0 / physics.sim_freq))
        self.substeps = int(pick(substeps, physics.newton_substeps))
        self.sub_dt = self.dt / self.substeps
        self.iterations = int(pick(iterations, physics.vbd_iterations))
        self.contact_ke = float(pick(contact_ke, physics.soft_contact_ke))
        self.contact_kd = float(pick(contact_kd, physics.soft_contact_kd))
        particle_radius = pick(particle_radius, physics.particle_radius)
        contact_gap = pick(contact_gap, physics.soft_contact_gap)
        self.particle_radius = float(particle_radius)
        self.contact_gap = float(contact_gap)
        self.use_graph = use_graph
        self.device = wp.get_device(device)
        self.builder = newton.ModelBuilder(gravity=(0.0, 0.0, float(gravity)))
        self.soft_bodies: list[SoftBodyHandle] = []
        self.colliders: list[ColliderHandle] = []
        self.model = None
        self.time = 0.0
        # Sleeping (see physics.sleeping): off unless asked for, so physics tests see every tick.
        self.sleeping = bool(sleeping)
        self._asleep = np.zeros(0, bool)  # per soft body
        self._quiet = np.zeros(0, int)  # per soft body: consecutive quiet ticks
        self._sleep_wrench = None  # returned while every body sleeps
        self.sleep_stats = {"ticks_simulated": 0, "ticks_asleep": 0}

    # ------------------------------------------------------------------ building
    def add_soft_body(
        self,
        name: str,
        vertices: np.ndarray,
        tets: np.ndarray,
        material: SoftMaterial,
        pose: np.ndarray = C.IDENTITY_POSE,
    ) -> SoftBodyHandle:
        """Add a tetrahedral body. ``vertices`` in its local frame, ``pose`` SAPIEN order [p, q_wxyz]."""
        self._require_building()
        vertices = np.asarray(vertices, dtype=np.float64)
        tets = np.asarray(tets, dtype=np.int32)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4:
            raise ValueError(f"soft body '{name}': need vertices (N,3) and tets (M,4), got {vertices.shape}, {tets.shape}")
        if tets.min() < 0 or tets.max() >= len(vertices):
            raise ValueError(f"soft body '{name}': tet indices out of range [0, {len(vertices)})")
        vols = tet_volumes(vertices, tets)
        if vols.min() <= 0:
            raise ValueError(
                f"soft body '{name}': {int((vols <= 0).sum())} inverted or degenerate tets; "
                "re-mesh the object (mani_skill_softvt.assets.tetmesh)"
            )
        mu, lam = lame_parameters(material.youngs_modulus, material.poisson_ratio)
        b = self.builder
        p0, t0 = len(b.particle_q), len(b.tet_indices)
        pose = sapien_pose_to_newton(pose)
        b.add_soft_mesh(
            pos=wp.vec3(*pose[:3]),
            rot=wp.quat(*pose[3:7]),
            scale=1.0,
            vel=wp.vec3(0.0, 0.0, 0.0),
            vertices=[wp.vec3(*v) for v in vertices],
            indices=tets.reshape(-1).tolist(),
            density=material.density,
            k_mu=mu,
            k_lambda=lam,
            k_damp=material.damping,
            particle_radius=self.particle_radius,
            add_surface_mesh_edges=False,
            label=name,
        )
        # Newton's lumping does not sum to density*volume for every mesh: impose the FEM lumped
        # mass so that the body weighs exactly density * volume.
        masses = lumped_node_masses(vertices, tets, material.density)
        for i, m in enumerate(masses):
            b.particle_mass[p0 + i] = float(m)
        h = SoftBodyHandle(name, p0, len(vertices), t0, len(tets), material, vertices, tets)
        self.soft_bodies.append(h)
        return h

    def _new_collider(self, name: str, movable: bool) -> ColliderHandle:
        self._require_building()
        if any(c.name == name for c in self.colliders):
            raise ValueError(f"collider '{name}' already exists")
        body = self.builder.add_body(xform=wp.transform_identity(), mass=0.0, is_kinematic=True, label=name)
        h = ColliderHandle(name, body, movable=bool(movable))
        self.colliders.append(h)
        return h

    def _shape_cfg(self, friction: float) -> newton.ModelBuilder.ShapeConfig:
        cfg = newton.ModelBuilder.ShapeConfig(
            density=0.0, mu=friction, ke=self.contact_ke, kd=self.contact_kd, gap=self.contact_gap
        )
        # Colliders are posed by SAPIEN; only their contacts with the soft particles matter here.
        cfg.has_shape_collision = False
        cfg.has_particle_collision = True
        return cfg

    def add_collider_box(self, name: str, half_extents, local_pose=C.IDENTITY_POSE, friction: float = 1.0,
                         movable: bool = False):
        """A kinematic box collider; ``local_pose`` places the box in the collider's frame.

        ``movable`` marks a collider that may push a soft body at any time (a robot link): a body
        it comes near never sleeps (see :mod:`~mani_skill_softvt.physics.sleeping`)."""
        h = self._new_collider(name, movable)
        lp = sapien_pose_to_newton(local_pose)
        h.bound_points.append(box_corners(half_extents, lp))
        s = self.builder.add_shape_box(
            h.body,
            xform=wp.transform(wp.vec3(*lp[:3]), wp.quat(*lp[3:7])),
            hx=float(half_extents[0]),
            hy=float(half_extents[1]),
            hz=float(half_extents[2]),
            cfg=self._shape_cfg(friction),
            label=f"{name}/box",
        )
        h.shapes.append(s)
        return h

    def add_collider_boxes(self, name: str, boxes, friction: float = 1.0, movable: bool = False):
        """A kinematic collider made of several boxes: ``[(half_extents, local_pose), ...]``."""
        h = self._new_collider(name, movable)
        for i, (he, local_pose) in enumerate(boxes):
            lp = sapien_pose_to_newton(local_pose)
            h.bound_points.append(box_corners(he, lp))
            h.shapes.append(
                self.builder.add_shape_box(
                    h.body,
                    xform=wp.transform(wp.vec3(*lp[:3]), wp.quat(*lp[3:7])),
                    hx=float(he[0]), hy=float(he[1]), hz=float(he[2]),
                    cfg=self._shape_cfg(friction),
                    label=f"{name}/box{i}",
                )
            )
        return h

    def add_collider_convex(self, name: str, parts, friction: float = 1.0, movable: bool = False):
        """A kinematic collider made of convex parts: list of (vertices (N,3), faces (F,3))."""
        h = self._new_collider(name, movable)
        for i, (v, f) in enumerate(parts):
            h.bound_points.append(np.asarray(v, np.float64).reshape(-1, 3))
            mesh = newton.Mesh(np.asarray(v, np.float32), np.asarray(f, np.int32).reshape(-1))
            h.shapes.append(
                self.builder.add_shape_convex_hull(h.body, mesh=mesh, cfg=self._shape_cfg(friction), label=f"{name}/part{i}")
            )
        return h

    def _require_building(self):
        if self.model is not None:
            raise RuntimeError("SoftBodyWorld is finalized; add bodies and colliders before finalize()")

    # ------------------------------------------------------------------ finalize
    def finalize(self) -> None:
        if not self.soft_bodies:
            raise ValueError("SoftBodyWorld needs at least one soft body before finalize()")
        self.builder.color()
        self.model = m = self.builder.finalize(device=self.device)
        # Particle-side contact material; VBD averages it with each shape's own.
        m.soft_contact_ke = self.contact_ke
        m.soft_contact_kd = self.contact_kd
        m.soft_contact_mu = float(self.soft_bodies[0].material.friction)
        self.pipeline = newton.CollisionPipeline(m, broad_phase="nxn", soft_contact_gap=self.contact_gap)
        self.contacts = self.pipeline.contacts()
        self.solver = newton.solvers.SolverVBD(
            m,
            iterations=self.iterations,
            friction_epsilon=self.physics.friction_epsilon,
            integrate_with_external_rigid_solver=True,
            particle_enable_tile_solve=False,  # measured faster on CPU for ~300-node bodies
        )
        self.state_in = m.state()
        self.state_out = m.state()
        self.control = m.control()
        self.observables = self.solver.observables(
            [newton.solvers.SolverBase.ObservableKind.CONTACT_F], contacts=self.contacts
        )
        self._soft_row_offset = int(self.contacts.rigid_contact_max)
        self.body_wrench = wp.zeros(m.body_count, dtype=wp.spatial_vector, device=self.device)
        self._q_start = wp.zeros(m.body_count, dtype=wp.transform, device=self.device)
        self._q_end = wp.zeros(m.body_count, dtype=wp.transform, device=self.device)
        self._collider_q = np.tile(np.array([0, 0, 0, 0, 0, 0, 1], np.float32), (m.body_count, 1))
        self._nominal_tet_materials = m.tet_materials.numpy().copy()
        self._nominal_particle_mass = m.particle_mass.numpy().copy()
        self._graph = None
        self.material_scale = {"youngs_modulus": 1.0, "mass": 1.0}
        boxes = [local_bounds(np.concatenate(c.bound_points)) for c in self.colliders]
        self._bound_min = np.array([lo for lo, _ in boxes]).reshape(-1, 3)
        self._bound_max = np.array([hi for _, hi in boxes]).reshape(-1, 3)
        self._movable = np.array([c.movable for c in self.colliders], bool)
        self._collider_bodies = np.array([c.body for c in self.colliders], int)
        # Awake until a collider comes closer than this to a body's bounds (see physics.sleeping).
        self.wake_distance = self.contact_gap + self.particle_radius + WAKE_MARGIN
        self._asleep = np.zeros(len(self.soft_bodies), bool)
        self._quiet = np.zeros(len(self.soft_bodies), int)
        self._active_flags = m.particle_flags.numpy().copy()

    # ------------------------------------------------------------------ stepping
    def _simulate(self):
        """One tick: ``substeps`` Newton steps with colliders interpolated from start to end pose."""
        self.body_wrench.zero_()
        for k in range(self.substeps):
            for q, alpha in ((self.state_in.body_q, k / self.substeps), (self.state_out.body_q, (k + 1) / self.substeps)):
                wp.launch(_interpolate_body_q, dim=self.model.body_count, inputs=[self._q_start, self._q_end, alpha],
                          outputs=[q], device=self.device)
            self.state_in.clear_forces()
            self.pipeline.collide(self.state_in, self.contacts)
            self.solver.step(
                self.state_in, self.state_out, self.control, self.contacts, self.sub_dt, observables=self.observables
            )
            # Sum of substep wrenches; divided by ``substeps`` in step() to give the tick average.
            wp.launch(
                _sum_soft_contact_wrenches,
                dim=self.contacts.soft_contact_max,
                inputs=[
                    self.contacts.soft_contact_count,
                    self.contacts.soft_contact_shape,
                    self.contacts.soft_contact_particle,
                    self.model.particle_flags,
                    self.model.shape_body,
                    self.observables.contact_f,
                    self._soft_row_offset,
                ],
                outputs=[self.body_wrench],
                device=self.device,
            )
            # Ping-pong by copy so that a captured graph always reads state_in and writes state_out.
            wp.copy(self.state_in.particle_q, self.state_out.particle_q)
            wp.copy(self.state_in.particle_qd, self.state_out.particle_qd)

    def set_collider_poses(self, poses: np.ndarray) -> None:
        """End-of-step poses of all colliders, SAPIEN order (n_colliders, 7), in collider order."""
        poses = np.asarray(poses, dtype=np.float64)
        if poses.shape != (len(self.colliders), 7) or not np.all(np.isfinite(poses)):
            raise ValueError(f"collider poses must be finite, shape ({len(self.colliders)}, 7); got {poses.shape}")
        q = np.zeros_like(self._collider_q)
        q[[c.body for c in self.colliders]] = sapien_pose_to_newton(poses).astype(np.float32)
        self._pending_q = q

    def reset_collider_poses(self, poses: np.ndarray) -> None:
        """Teleport colliders (no velocity): start and end poses of the next step both equal ``poses``."""
        self.set_collider_poses(poses)
        self._collider_q = self._pending_q

    @property
    def asleep(self) -> bool:
        """Every soft body sleeps: ticks are skipped altogether."""
        return bool(self._asleep.size and self._asleep.all())

    def bodies_asleep(self) -> np.ndarray:
        """Which soft bodies sleep (bool per body, in the order they were added)."""
        return self._asleep.copy()

    def _disturbed(self, new_q: np.ndarray) -> np.ndarray:
        """Per soft body: a movable collider, or one that moved this tick, ends the tick near it."""
        ends, starts = new_q[self._collider_bodies], self._collider_q[self._collider_bodies]
        candidates = self._movable | np.any(ends != starts, axis=1)
        out = np.zeros(len(self.soft_bodies), bool)
        if not candidates.any():
            return out
        q = self.state_in.particle_q.numpy()
        w_min, w_max = world_boxes(ends[candidates].astype(np.float64), self._bound_min[candidates],
                                   self._bound_max[candidates])  # posed once, checked against each body
        for i, h in enumerate(self.soft_bodies):
            v = q[h.particle_start : h.particle_start + h.particle_count]
            out[i] = bool((box_gap(w_min, w_max, v.min(0), v.max(0)) <= self.wake_distance).any())
        return out

    def _set_asleep(self, asleep: np.ndarray) -> None:
        """Put bodies to sleep or wake them: a sleeping body's particles are inactive for VBD (not
        moved, velocity zero) and its quiet count restarts."""
        asleep = np.asarray(asleep, bool)
        changed = asleep != self._asleep
        if not changed.any():
            return
        flags = self._active_flags.copy()
        qd = self.state_in.particle_qd.numpy()
        for i, h in enumerate(self.soft_bodies):
            sl = slice(h.particle_start, h.particle_start + h.particle_count)
            if asleep[i]:
                flags[sl] &= ~int(newton.ParticleFlags.ACTIVE)
                if changed[i]:
                    qd[sl] = 0.0  # asleep is at rest
        self.model.particle_flags.assign(flags)
        self.state_out.particle_qd.assign(qd)
        self._quiet[changed] = 0
        self._asleep = asleep.copy()

    def step(self) -> np.ndarray:
        """Advance one time step; returns the contact wrench on each collider, (n_colliders, 6).

        Row layout: [force (3), torque about the collider frame origin (3)], world frame, N and N*m.
        With ``sleeping`` (see :mod:`~mani_skill_softvt.physics.sleeping`), sleeping bodies are not
        simulated, and a tick in which every body sleeps is skipped: the colliders move, the nodes
        and the wrenches stay as they were.
        """
        if self.model is None:
            raise RuntimeError("call finalize() before step()")
        new_q = getattr(self, "_pending_q", self._collider_q)
        disturbed = self._disturbed(new_q) if self.sleeping else np.zeros(len(self.soft_bodies), bool)
        if self.asleep and not disturbed.any():
            self._end_tick(new_q, "ticks_asleep")
            return self._sleep_wrench.copy()
        self._set_asleep(self._asleep & ~disturbed)
        self._simulate_tick(new_q)
        self._end_tick(new_q, "ticks_simulated")
        w = self.body_wrench.numpy()[self._collider_bodies].astype(np.float64) / self.substeps
        if self.sleeping:
            self._count_quiet_ticks(disturbed, w)
        return w

    def _simulate_tick(self, new_q: np.ndarray) -> None:
        """One simulated tick with the colliders moving from their poses to ``new_q``: through the
        captured graph where there is one (the simulation itself is :meth:`_simulate`)."""
        qd = np.zeros((len(new_q), 6), np.float32)
        qd[:, :3] = (new_q[:, :3] - self._collider_q[:, :3]) / self.dt  # Newton: linear first
        qd[:, 3:] = angular_velocity_xyzw(self._collider_q[:, 3:], new_q[:, 3:], self.dt)
        self._q_start.assign(self._collider_q)
        self._q_end.assign(new_q)
        self.state_in.body_qd.assign(qd)
        self.state_out.body_qd.assign(qd)
        if self._graph is not None:
            wp.capture_launch(self._graph)
            return
        self._simulate()
        if self.use_graph:
            # Capture after one uncaptured tick (the solver sizes its contact buffers on the
            # first step). CPU capture records without executing, so no tick is run twice.
            with wp.ScopedCapture(device=self.device) as cap:
                self._simulate()
            self._graph = cap.graph

    def _end_tick(self, new_q: np.ndarray, stat: str) -> None:
        self._collider_q = new_q
        self._pending_q = new_q
        self.time += self.dt
        self.sleep_stats[stat] += 1

    def _count_quiet_ticks(self, disturbed: np.ndarray, wrench: np.ndarray) -> None:
        """The sleep rule after a simulated tick: count each awake body's quiet ticks, put to sleep
        those quiet long enough, and keep the wrench a tick of all-asleep bodies returns."""
        qd = self.state_in.particle_qd.numpy().astype(np.float64)
        for i, h in enumerate(self.soft_bodies):
            if self._asleep[i]:
                continue
            v = qd[h.particle_start : h.particle_start + h.particle_count]
            self._quiet[i] = self._quiet[i] + 1 if is_quiet(float(np.sqrt((v**2).sum(1).max())), disturbed[i]) else 0
        self._set_asleep(self._asleep | (self._quiet >= SLEEP_TICKS))
        if self.asleep:
            self._sleep_wrench = wrench.copy()

    # ------------------------------------------------------------------ state access
    def particle_q(self, body: int | SoftBodyHandle = 0) -> np.ndarray:
        h = self._handle(body)
        return self.state_in.particle_q.numpy()[h.particle_start : h.particle_start + h.particle_count].astype(np.float64)

    def particle_qd(self, body: int | SoftBodyHandle = 0) -> np.ndarray:
        h = self._handle(body)
        return self.state_in.particle_qd.numpy()[h.particle_start : h.particle_start + h.particle_count].astype(np.float64)

    def damp_velocities(self, factor: float) -> None:
        """Scale every node velocity by ``factor`` (settling only: drains kinetic energy, e.g. rocking)."""
        qd = self.state_in.particle_qd.numpy()
        qd *= np.float32(factor)

    def _handle(self, body) -> SoftBodyHandle:
        return body if isinstance(body, SoftBodyHandle) else self.soft_bodies[body]

    def get_state(self) -> dict[str, np.ndarray]:
        """Everything needed to continue bit-identically: particle positions/velocities, collider
        poses, and the sleep state (asleep, quiet ticks so far; the wrench it returns while asleep)."""
        n = len(self.colliders)
        return {
            "particle_q": self.state_in.particle_q.numpy().copy(),
            "particle_qd": self.state_in.particle_qd.numpy().copy(),
            "collider_q": self._collider_q.copy(),
            "time": np.array(self.time),
            "sleep": np.concatenate([self._asleep, self._quiet]).astype(np.float64),
            "sleep_wrench": self._sleep_wrench.copy() if self.asleep else np.zeros((n, 6)),
        }

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        for key in ("particle_q", "particle_qd", "collider_q"):
            if key not in state:
                raise KeyError(f"soft-body state is missing '{key}'")
        if state["particle_q"].shape != (self.model.particle_count, 3):
            raise ValueError(f"particle_q shape {state['particle_q'].shape} != ({self.model.particle_count}, 3)")
        for s in (self.state_in, self.state_out):
            s.particle_q.assign(state["particle_q"].astype(np.float32))
            s.particle_qd.assign(state["particle_qd"].astype(np.float32))
        self._collider_q = state["collider_q"].astype(np.float32).copy()
        self._pending_q = self._collider_q
        self.time = float(state.get("time", 0.0))
        n = len(self.soft_bodies)
        sleep = np.asarray(state.get("sleep", np.zeros(2 * n)), np.float64)  # saved before sleeping existed: awake
        if sleep.shape != (2 * n,):
            raise ValueError(f"sleep state must hold 2 x {n} values (asleep, quiet ticks per body), got {sleep.shape}")
        self._set_asleep(sleep[:n] > 0)  # particle flags follow
        self._quiet = sleep[n:].astype(int)
        self._sleep_wrench = np.asarray(state["sleep_wrench"], np.float64).copy() if self.asleep else None
        # VBD keeps per-step scratch (previous positions, contact warm starts) that is rebuilt
        # from state_in at every step, so positions + velocities are the full state.

    def set_soft_body_pose(self, body: int | SoftBodyHandle, pose: np.ndarray, vertices: np.ndarray | None = None):
        """Place a soft body (rest shape, or ``vertices`` in its local frame) at ``pose``, at rest."""
        h = self._handle(body)
        v = h.rest_vertices if vertices is None else np.asarray(vertices, np.float64)
        m = pose_wxyz_to_matrix(np.asarray(pose, np.float64))
        world = v @ m[:3, :3].T + m[:3, 3]
        q = self.state_in.particle_q.numpy()
        qd = self.state_in.particle_qd.numpy()
        q[h.particle_start : h.particle_start + h.particle_count] = world
        qd[h.particle_start : h.particle_start + h.particle_count] = 0.0
        for s in (self.state_in, self.state_out):
            s.particle_q.assign(q)
            s.particle_qd.assign(qd)
        self.wake()

    def wake(self) -> None:
        """Simulate from the next tick on (a teleport, new materials: the body must respond)."""
        if self.model is not None:
            self._set_asleep(np.zeros(len(self.soft_bodies), bool))
        self._quiet[:] = 0
        self._sleep_wrench = None

    # ------------------------------------------------------------------ OOD rescaling
    def scale_materials(self, youngs_modulus: float = 1.0, mass: float = 1.0) -> None:
        """Rescale Young's modulus and mass of every soft body in place, relative to nominal.

        Both Lame parameters scale linearly with E (Poisson ratio unchanged); node masses and
        inverse masses scale together. No kernel is rebuilt and the captured graph stays valid
        because the arrays are updated in place.
        """
        if not (youngs_modulus > 0 and mass > 0):
            raise ValueError(f"scales must be positive, got E x{youngs_modulus}, mass x{mass}")
        mat = self._nominal_tet_materials.copy()
        mat[:, 0:2] *= youngs_modulus  # columns: k_mu, k_lambda, k_damp
        self.model.tet_materials.assign(mat)
        pm = self._nominal_particle_mass * mass
        self.model.particle_mass.assign(pm)
        inv = np.where(pm > 0, 1.0 / np.where(pm > 0, pm, 1.0), 0.0).astype(np.float32)
        self.model.particle_inv_mass.assign(inv)
        self.material_scale = {"youngs_modulus": float(youngs_modulus), "mass": float(mass)}
        self.wake()

    # ------------------------------------------------------------------ health
    def check_health(self, max_speed: float = C.MAX_PARTICLE_SPEED) -> None:
        """Raise :class:`SimulationInstabilityError` with the reason if the FEM blew up.

        A collapsed or inverted tet is not a blow-up (:meth:`collapsed_tets`): VBD's Neo-Hookean
        energy is defined through inversion and pushes it back out, and the body simulates on; the
        evaluator scores it instead."""
        q = self.state_in.particle_q.numpy()
        qd = self.state_in.particle_qd.numpy()
        if not np.all(np.isfinite(q)) or not np.all(np.isfinite(qd)):
            raise SimulationInstabilityError(
                f"FEM state contains NaN/inf at t={self.time:.4f} s; reduce the time step or contact stiffness"
            )
        speed = float(np.linalg.norm(qd, axis=1).max())
        if speed > max_speed:
            raise SimulationInstabilityError(
                f"FEM node speed {speed:.2f} m/s exceeds {max_speed} m/s at t={self.time:.4f} s (exploding simulation)"
            )

    def collapsed_tets(self, index: int) -> int:
        """How many tets of soft body ``index`` are collapsed or inverted (volume <=
        ``MIN_TET_VOLUME_RATIO`` x rest): there the mesh no longer represents the local compression."""
        h = self.soft_bodies[index]
        return collapsed_count(self.particle_q(index), h.rest_vertices, h.tets)

