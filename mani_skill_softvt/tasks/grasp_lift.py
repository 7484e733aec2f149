"""SoftGraspLift-v1: grasp a soft cube from the table, lift it and hold it.

The foundation scene (no target container): the physics every suite builds on, used by the
README demo, the coupling tests and the speed benchmark.

**Task Description:** pick up the soft cube lying on the table and hold it 10 cm above the table.

**Randomizations:** the cube's xy position within +-2 cm of the nominal spot and its yaw
within +-15 deg (from the episode seed).

**Success Conditions:** the cube's lowest node is at least 9 cm above the table and the cube
is between the fingers.
"""

from __future__ import annotations

import numpy as np
import sapien
import torch
from mani_skill.utils.registration import register_env

from ..assets.tetmesh import box_tetmesh
from ..physics.fem import SoftMaterial
from ..physics.transforms import wxyz_to_xyzw  # noqa: F401
from . import constants as C
from .soft_body_env import SoftBodyEnv, SoftObjectSpec

CUBE_SIZE = 0.05
CUBE_MATERIAL = SoftMaterial(youngs_modulus=5e4, poisson_ratio=0.3, density=300.0, damping=1.0, friction=1.0)
NOMINAL_XY = np.array([0.0, 0.0])


@register_env("SoftGraspLift-v1", max_episode_steps=C.MAX_EPISODE_STEPS)
class SoftGraspLiftEnv(SoftBodyEnv):
    def __init__(self, *args, cube_size: float = CUBE_SIZE, resolution: int = 6,
                 material: SoftMaterial = CUBE_MATERIAL, **kwargs):
        self.cube_size, self.resolution, self.material = cube_size, resolution, material
        super().__init__(*args, **kwargs)

    def _soft_object_specs(self):
        v, t = box_tetmesh((self.cube_size,) * 3, self.resolution)
        return [SoftObjectSpec("cube", v, t, self.material, color=(0.93, 0.87, 0.7, 1.0))]

    def _initialize_task(self, env_idx, options):
        rng = self._episode_rng
        qpos = np.array([0.0, np.pi / 8, 0, -np.pi * 5 / 8, 0, np.pi * 3 / 4, np.pi / 4, C.GRIPPER_Q_OPEN, C.GRIPPER_Q_OPEN])
        self.agent.reset(torch.as_tensor(qpos[None], dtype=torch.float32))
        xy = NOMINAL_XY + rng.uniform(-0.02, 0.02, size=2)
        yaw = rng.uniform(-np.pi / 12, np.pi / 12)
        q = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
        self.cube_yaw = yaw
        return {"cube": np.array([xy[0], xy[1], 0.0, *q])}

    def evaluate(self):
        nodes = self.soft_nodes("cube")
        lifted = nodes[:, 2].min() >= 0.09
        tcp = self.agent.tcp.pose.p[0].cpu().numpy()
        between = np.linalg.norm(nodes.mean(axis=0)[:2] - tcp[:2]) < 0.03
        return {"success": torch.tensor([bool(lifted and between)]), "lifted": torch.tensor([bool(lifted)])}

    def _get_obs_extra(self, info):
        return {"tcp_pose": self.agent.tcp.pose.raw_pose}

    def compute_dense_reward(self, obs, action, info):
        return info["success"].float()

    def compute_normalized_dense_reward(self, obs, action, info):
        return self.compute_dense_reward(obs, action, info)
