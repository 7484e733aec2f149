"""SoftGraspLift-v1: grasp a soft object from the table, lift it and hold it.

The foundation scene (no target container): the physics every suite builds on, used by the
grasp demo (``python -m mani_skill_softvt.cli.grasp_demo``), the coupling tests and the speed benchmark.

**Task Description:** pick up the object lying on the table (by default the soft cream-colored
cube; any asset id or rigid twin via ``asset_id=...``) and hold it 10 cm above the table.

**Randomizations:** the object's xy position within +-2 cm of the nominal spot and its yaw
within +-15 deg (from the episode seed).

**Success Conditions:** the object's lowest node is at least 9 cm above the table and the
object is between the fingers.
"""

from __future__ import annotations

import numpy as np
import torch
from mani_skill.utils.registration import register_env

from ..assets import load_card
from . import constants as C
from .soft_body_env import SoftBodyEnv, ObjectSpec

DEFAULT_ASSET = "soft_stw_cube_hq"
NOMINAL_XY = np.array([0.0, 0.0])


@register_env("SoftGraspLift-v1", max_episode_steps=C.MAX_EPISODE_STEPS)
class SoftGraspLiftEnv(SoftBodyEnv):
    def __init__(self, *args, asset_id: str = DEFAULT_ASSET, **kwargs):
        self.asset_card = load_card(asset_id)
        super().__init__(*args, **kwargs)

    def _object_specs(self):
        return [ObjectSpec.from_card("object", self.asset_card)]

    def _initialize_task(self, env_idx, options):
        rng = self._episode_rng
        qpos = C.ROBOT_REST_QPOS.copy()
        self.agent.reset(torch.as_tensor(qpos[None], dtype=torch.float32))
        xy = NOMINAL_XY + rng.uniform(-0.02, 0.02, size=2)
        yaw = rng.uniform(-np.pi / 12, np.pi / 12)
        q = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
        return {"object": np.array([xy[0], xy[1], 0.0, *q])}

    def evaluate(self):
        nodes = self.soft_nodes("object")
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
