"""Rigid twins as PhysX rigid bodies, seen through the same node accessors as the FEM bodies.

A rigid twin is simulated by SAPIEN/PhysX like any ManiSkill object (convex collision parts,
mass, friction, colour), so it costs what PickCube's cube costs and never deforms. The rest of
the package (expert, success predicates, deformation metric) reads objects as
nodes: a twin's "nodes" are its soft asset's tet nodes carried by the body's pose, so D_t of a
twin is zero up to float rounding, measured by the same metric as a soft object. What the gel
touches is another surface: the convex hulls PhysX cooked from the collision parts
(:func:`collision_parts`), the surface PhysX actually keeps at the pad. The tet boundary can sit
some 0.35 mm outside it, which would read as the whole pad pressed at any force.

Pure functions (:func:`rigid_nodes`, :func:`rigid_node_velocities`, :func:`contact_wrench`) hold
the maths; :class:`RigidObject` is the thin handle on the SAPIEN component.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import sapien
from scipy.spatial import ConvexHull

from ..assets.tetmesh import join_meshes
from .transforms import pose_wxyz_to_matrix


def rigid_nodes(rest_nodes: np.ndarray, pose7: np.ndarray) -> np.ndarray:
    """World positions (N, 3) of points fixed in a body (``rest_nodes`` in its frame) at pose [p, q_wxyz]."""
    m = pose_wxyz_to_matrix(np.asarray(pose7, np.float64))
    return np.asarray(rest_nodes, np.float64) @ m[:3, :3].T + m[:3, 3]


def rigid_node_velocities(nodes: np.ndarray, com: np.ndarray, linear: np.ndarray, angular: np.ndarray) -> np.ndarray:
    """Velocities (N, 3) of body points ``nodes`` (world): v = v_com + omega x (x - com)."""
    return np.asarray(linear, np.float64) + np.cross(np.asarray(angular, np.float64), np.asarray(nodes) - com)


def collision_parts(component: sapien.physx.PhysxRigidBaseComponent) -> list[tuple[np.ndarray, np.ndarray]]:
    """Vertices (body frame) and triangles of each convex collision shape of ``component`` as
    PhysX cooked it (a hull of at most 255 vertices, not the file's mesh). The triangles are the
    convex hull's of the cooked vertices: PhysX's own triangulation of a hull polygon whose
    vertices sit off its plane is not convex (0.2 mm of ridge across the cube twin's face)."""
    parts = []
    for shape in component.get_collision_shapes():
        if not isinstance(shape, sapien.physx.PhysxCollisionShapeConvexMesh):
            raise ValueError(f"{component.entity.name}: a rigid twin's collision parts are convex meshes, "
                             f"got a {type(shape).__name__}")
        local = np.r_[shape.local_pose.p, shape.local_pose.q].astype(np.float64)
        # get_vertices() is the unscaled mesh (ManiSkill's trimesh_utils scales it the same way).
        v = rigid_nodes(np.asarray(shape.get_vertices(), np.float64) * np.asarray(shape.scale, np.float64), local)
        parts.append((v, ConvexHull(v).simplices))
    if not parts:
        raise ValueError(f"{component.entity.name}: a rigid twin without collision shapes has no surface to touch")
    return parts


def contact_wrench(points: Iterable[tuple[np.ndarray, np.ndarray]], dt: float, about: np.ndarray) -> np.ndarray:
    """[force (3) N, torque (3) N m about ``about``] of contact impulses ``(position, impulse)``
    received over one step of ``dt`` seconds."""
    w = np.zeros(6)
    for position, impulse in points:
        f = np.asarray(impulse, np.float64) / dt
        w[:3] += f
        w[3:] += np.cross(np.asarray(position, np.float64) - about, f)
    return w


class RigidObject:
    """A rigid twin in the SAPIEN scene: ``component`` is its PhysX rigid dynamic body and
    ``rest_nodes`` the evaluation nodes in its frame (the frame objects are placed in: bottom at z = 0)."""

    def __init__(self, name: str, component: sapien.physx.PhysxRigidDynamicComponent, rest_nodes: np.ndarray,
                 mass: float):
        self.name = name
        self.component = component
        self.rest_nodes = np.asarray(rest_nodes, np.float64)
        self.nominal_mass = float(mass)
        self._inertia = np.asarray(component.inertia, np.float64) * (self.nominal_mass / component.mass)
        self.scale_mass(1.0)
        self.surface_parts = collision_parts(component)  # body frame; fixed
        self._surface_vertices, self._surface_faces = join_meshes(self.surface_parts)

    def surface(self) -> tuple[np.ndarray, np.ndarray]:
        """World vertices and triangles of the surface PhysX collides (:func:`collision_parts`, as one mesh)."""
        return rigid_nodes(self._surface_vertices, self.pose7()), self._surface_faces

    @property
    def entity(self) -> sapien.Entity:
        return self.component.entity

    def pose7(self) -> np.ndarray:
        p = self.entity.pose
        return np.concatenate([p.p, p.q]).astype(np.float64)

    def nodes(self) -> np.ndarray:
        return rigid_nodes(self.rest_nodes, self.pose7())

    def node_velocities(self) -> np.ndarray:
        c = self.component
        com = (self.entity.pose * c.cmass_local_pose).p
        return rigid_node_velocities(self.nodes(), np.asarray(com, np.float64), c.linear_velocity, c.angular_velocity)

    def set_pose(self, pose7: np.ndarray) -> None:
        """Teleport to [p, q_wxyz] at rest."""
        pose7 = np.asarray(pose7, np.float64)
        self.entity.set_pose(sapien.Pose(p=pose7[:3], q=pose7[3:]))
        self.component.set_linear_velocity(np.zeros(3))
        self.component.set_angular_velocity(np.zeros(3))

    def speed(self) -> float:
        """Fastest node speed (m/s)."""
        return float(np.abs(self.node_velocities()).max())

    def damp_velocities(self, factor: float) -> None:
        c = self.component
        c.set_linear_velocity(np.asarray(c.linear_velocity) * factor)
        c.set_angular_velocity(np.asarray(c.angular_velocity) * factor)

    def scale_mass(self, scale: float) -> None:
        """Mass (and inertia with it: same shape, density scaled) to ``scale`` x the card's mass."""
        self.component.set_mass(self.nominal_mass * scale)
        self.component.set_inertia((self._inertia * scale).astype(np.float32))

    @property
    def mass(self) -> float:
        return float(self.component.mass)

    def contact_wrench(self, contacts, other: sapien.Entity, dt: float, about: np.ndarray) -> np.ndarray:
        """Wrench this object exerts on ``other`` over the last step, from PhysX ``contacts``
        (torque about ``about``, world frame)."""
        me = self.entity

        def points():
            for c in contacts:
                e0, e1 = c.bodies[0].entity, c.bodies[1].entity
                # PhysX reports each point's impulse as received by bodies[0].
                if e0 == other and e1 == me:
                    sign = 1.0
                elif e0 == me and e1 == other:
                    sign = -1.0
                else:
                    continue
                for pt in c.points:
                    yield pt.position, sign * np.asarray(pt.impulse)

        return contact_wrench(points(), dt, about)
