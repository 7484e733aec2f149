"""The Panda's fingers as the objects and the GelSights meet them: pad poses, inertia, colliders.

Both object back ends (:mod:`.objects`) and the tactile sensors read the fingers through these
functions; the env only wires them up.
"""

from __future__ import annotations

import numpy as np
import trimesh
from mani_skill import PACKAGE_ASSET_DIR

from ..physics.transforms import pose_wxyz_to_matrix
from ..contracts.observations import SIDES
from ..tactile.sensor import finger_pad_frame
from . import constants as C

FINGER_LINKS = {side: f"panda_{side}finger" for side in SIDES}
HAND_LINK = "panda_hand"
FEEDBACK_LINKS = (*FINGER_LINKS.values(), HAND_LINK)  # robot links objects push back on


def set_finger_inertia(robot) -> None:
    """Give each finger the reflected inertia of the Franka gripper's geared drive.

    Contact forces return to SAPIEN one tick late, which is stable only while
    omega * dt < 2 with omega = sqrt(k_contact / m_finger). Against a stiff object (a rigid
    twin) k_contact ~ 1e5 N/m, so the URDF's bare 15 g finger would be thrown off the object;
    the geared gripper's reflected mass (~1 kg) is both realistic and stable.
    """
    for link in robot.get_links():
        if link.name in FINGER_LINKS.values():
            body = link._objs[0]
            scale = C.FINGER_EFFECTIVE_MASS / body.mass
            body.set_mass(C.FINGER_EFFECTIVE_MASS)
            body.set_inertia(np.asarray(body.inertia) * scale)


def _link_matrix(link) -> np.ndarray:
    # Link poses as numpy matrices directly (ManiSkill's batched torch conversion costs ~0.15 ms
    # a link, most of a tactile frame's overhead).
    return pose_wxyz_to_matrix(link.pose.raw_pose[0].cpu().numpy().astype(np.float64))


def pad_pose(robot, side: str, contact_radius: float) -> np.ndarray:
    """4x4 world pose of the ``side`` finger's gel surface (tactile pad frame, see tactile.sensor).

    The gel surface is the pad's inner face moved out by ``contact_radius``: where the objects'
    touching surface rests (FEM nodes keep their contact radius from a collider; PhysX bodies
    rest on the face itself), so the object's surface reaches it exactly when it touches the pad.
    """
    other = {"left": "right", "right": "left"}[side]
    links = robot.links_map
    centre = {}
    for s in (side, other):
        link = _link_matrix(links[FINGER_LINKS[s]])
        centre[s] = link[:3, :3] @ np.asarray(C.FINGERTIP_OFFSET[s]) + link[:3, 3]
    hand = _link_matrix(links[HAND_LINK])
    normal = centre[other] - centre[side]
    normal /= np.linalg.norm(normal)
    face = centre[side] + normal * (C.FINGERTIP_HALF_EXTENTS[1] + contact_radius)
    return finger_pad_frame(side, face, normal, hand[:3, 0].astype(np.float64))


def gripper_width(robot) -> float:
    """Jaw gap between the two fingertip pads (m)."""
    q = robot.get_qpos()[0, -2:].cpu().numpy()
    return float(q.sum())


def fingertip_box_pose(side: str) -> np.ndarray:
    """[p, q_wxyz] of the ``side`` fingertip's collision box in its finger link's frame."""
    return np.array([*C.FINGERTIP_OFFSET[side], 1.0, 0.0, 0.0, 0.0])


_HAND_HULL = None


def hand_collision_hull() -> tuple[np.ndarray, np.ndarray]:
    """Convex hull of the Panda hand's collision mesh (from the ManiSkill wheel), hand frame."""
    global _HAND_HULL
    if _HAND_HULL is None:
        m = trimesh.load(f"{PACKAGE_ASSET_DIR}/robots/panda/franka_description/meshes/collision/hand.stl", force="mesh")
        hull = m.convex_hull
        _HAND_HULL = (np.asarray(hull.vertices), np.asarray(hull.faces))
    return _HAND_HULL
