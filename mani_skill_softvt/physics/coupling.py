"""Two-way lockstep coupling between SAPIEN (robot, rigid scene) and Newton (soft bodies).

Every SAPIEN physics step is one Newton tick (lockstep at 240 Hz; 100 Hz with Newton substeps was
unstable: 15 g fingers, one-tick-late contact forces):

1. ``before_sapien_step``: the contact wrench Newton reported on each robot link in the previous
   tick is applied to that SAPIEN link (one tick late; stable at 240 Hz, not at 100 Hz).
2. SAPIEN steps (arm and gripper drives, the force-limited gripper feels the object).
3. ``after_sapien_step``: the new poses of all mirrored SAPIEN bodies (finger pads, hand, table,
   containers) become the end-of-tick collider poses in Newton; Newton steps and reports the
   wrench that the soft bodies exert on each collider.

Only kinematic quantities cross from SAPIEN to Newton and only wrenches come back, so adding a
batch dimension later (many worlds on a GPU) changes array shapes, not this protocol.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sapien

from .fem import SoftBodyWorld


@dataclass
class MirroredBody:
    """A SAPIEN rigid body (link or actor) that appears in Newton as a kinematic collider."""

    name: str
    component: sapien.physx.PhysxRigidBaseComponent
    feedback: bool  # apply the Newton contact wrench back to this body


def _pose7(pose: sapien.Pose) -> np.ndarray:
    return np.concatenate([pose.p, pose.q]).astype(np.float64)


class SapienNewtonCoupling:
    """Moves Newton colliders with SAPIEN bodies and feeds contact wrenches back."""

    def __init__(self, world: SoftBodyWorld, bodies: list[MirroredBody]):
        names = [c.name for c in world.colliders]
        if [b.name for b in bodies] != names:
            raise ValueError(f"mirrored bodies {[b.name for b in bodies]} must match the Newton colliders {names}")
        self.world = world
        self.bodies = bodies
        self.wrenches = np.zeros((len(bodies), 6))  # last tick's wrench per collider (world frame)

    def poses(self) -> np.ndarray:
        return np.stack([_pose7(b.component.entity_pose) for b in self.bodies])

    def teleport(self) -> None:
        """Place the colliders at the current SAPIEN poses with zero velocity (after a reset)."""
        self.world.reset_collider_poses(self.poses())
        self.wrenches[:] = 0.0

    def before_sapien_step(self) -> None:
        for body, w in zip(self.bodies, self.wrenches):
            if not body.feedback or not np.any(w):
                continue
            comp = body.component
            pose = comp.entity_pose
            com = (pose * comp.cmass_local_pose).p
            force = w[:3]
            # Newton reports torque about the collider frame origin; PhysX wants it about the COM.
            torque = w[3:] + np.cross(pose.p - com, force)
            comp.add_force_torque(force.astype(np.float32), torque.astype(np.float32), mode="force")

    def after_sapien_step(self) -> None:
        self.world.set_collider_poses(self.poses())
        self.wrenches = self.world.step()

    def wrench(self, name: str) -> np.ndarray:
        return self.wrenches[[b.name for b in self.bodies].index(name)]
