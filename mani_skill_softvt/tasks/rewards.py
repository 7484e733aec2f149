"""Dense reward of the pick-and-place tasks as pure functions, staged like ManiSkill's tabletop tasks.

Four stages, each worth at most 1, then success:

- reach: 1 - tanh(k_d * |TCP - object centroid|);
- grasp: 1 while the instructed object is grasped;
- place: 1 - tanh(k_d * |object centroid - target region centre|), while grasped or once in the target;
- release: 1 - tanh(k_v * |object centroid velocity|), once in the target and let go. It replaces the
  grasp term when the gripper opens over the target, so letting go does not lower the reward;
- success: :data:`DENSE_REWARD_MAX` (5), whatever the terms say.

Deformation beyond the calibrated tolerance costs ``DEFORMATION_PENALTY_WEIGHT * tanh(max(0, R_t - 1))``
with R_t = D_t / tau_o: nothing up to the tolerance (the envelope the calibration found safe), a
squeeze twice the tolerance costs ~0.76 of a stage, and the cost stays bounded so that one
instability cannot swamp the return. The sum is clipped to [0, DENSE_REWARD_MAX].

The benchmark's DSR asks for R_max <= 1 over the whole episode; a Markov reward sees only R_t, so
the penalty discourages over-squeezing while it happens and success is rewarded by the sparse
success alone (as the paper scores it). A collapsed tet (the evaluator's other violation,
evaluation/metrics.py) costs the penalty's bound while it lasts: the mesh cannot measure that
squeeze, so it is charged as the worst one.

Inputs are floats, numpy arrays or tensors (broadcast together); outputs are float32 tensors.
"""

from __future__ import annotations

import torch

DENSE_REWARD_MAX = 5.0  # four stages of at most 1, and success above all of them
DISTANCE_SCALE = 5.0  # 1/m, k_d: half the reach reward at 11 cm, as ManiSkill's PickCube
SPEED_SCALE = 10.0  # s/m, k_v: 0.8 at the 2 cm/s rest speed of success, ~0 while falling
DEFORMATION_PENALTY_WEIGHT = 1.0  # at most one stage: over-squeezing never pays for a grasp


def _tensor(x) -> torch.Tensor:
    return torch.as_tensor(x, dtype=torch.float32)


def distance_reward(distance, scale: float = DISTANCE_SCALE) -> torch.Tensor:
    """1 - tanh(scale * distance): 1 at zero distance, falling towards 0, in (0, 1]."""
    return 1.0 - torch.tanh(scale * _tensor(distance).clamp(min=0.0))


def rest_reward(speed, scale: float = SPEED_SCALE) -> torch.Tensor:
    """1 - tanh(scale * speed): 1 for an object at rest, in (0, 1]."""
    return 1.0 - torch.tanh(scale * _tensor(speed).clamp(min=0.0))


def deformation_penalty(ratio, weight: float = DEFORMATION_PENALTY_WEIGHT) -> torch.Tensor:
    """weight * tanh(max(0, R - 1)): zero within the tolerance (R <= 1), growing beyond, below ``weight``."""
    return weight * torch.tanh((_tensor(ratio) - 1.0).clamp(min=0.0))


def staged_reward(tcp_to_object, object_to_target, object_speed, grasped, in_target, success,
                  deformation_ratio, collapsed=False) -> torch.Tensor:
    """The dense reward of one step (see the module docstring), in [0, DENSE_REWARD_MAX].

    Distances in m, speed in m/s, the flags as bools (or 0/1), the deformation ratio R_t = D_t / tau_o,
    ``collapsed``: a tet of the scene is collapsed now.
    """
    grasped, in_target, success, collapsed = (_tensor(x).bool() for x in (grasped, in_target, success, collapsed))
    reward = distance_reward(tcp_to_object)
    reward = reward + grasped.float()
    # Carrying towards the target is rewarded only while the object goes with the hand (or has
    # arrived): pushing it across the table is not placing it.
    reward = reward + distance_reward(object_to_target) * (grasped | in_target).float()
    # Released in the target: the grasp term is gone, the object's coming to rest takes its place.
    reward = reward + rest_reward(object_speed) * (in_target & ~grasped).float()
    penalty = torch.where(collapsed, torch.tensor(DEFORMATION_PENALTY_WEIGHT), deformation_penalty(deformation_ratio))
    reward = (reward - penalty).clamp(0.0, DENSE_REWARD_MAX)
    return torch.where(success, torch.full_like(reward, DENSE_REWARD_MAX), reward)


def normalized_reward(reward) -> torch.Tensor:
    """A dense reward scaled to [0, 1] (1 on success)."""
    return _tensor(reward) / DENSE_REWARD_MAX
