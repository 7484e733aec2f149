"""Scripted pick-and-place expert for the four suites (privileged: reads the object's state).

Waypoints in Cartesian space, executed through the absolute end-effector pose controller
(whose IK plays the role of ManiSkill's motion planner in this free tabletop workspace):
approach above the instructed object, descend to mid-height, close to the episode's closure,
lift, transport above the target, lower, release, retreat, and wait for the object to settle.
The closure is drawn per episode from the object's calibrated envelope [g_min, g_max] (rigid
twins use their soft asset's card).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..tasks import constants as C
from .grasp_script import ee_action, mid_height_grasp

PHASE_STEPS = {"approach": 15, "descend": 15, "close": 12, "lift": 15, "transport": 25, "lower": 15,
               "release": 8, "retreat": 10, "wait": 10}
APPROACH_HEIGHT = 0.12  # m above the table (TCP)
CARRY_HEIGHT = 0.16  # m: clears the basket rim (6 cm) with the object hanging below the TCP
RELEASE_CLEARANCE = 0.015  # m between the object's bottom and the target floor at release


@dataclass
class ExpertPlan:
    closure: float
    waypoints: list = field(default_factory=list)  # [(phase, tcp xyz, gripper closure, yaw), ...]


def object_yaw(rest_vertices: np.ndarray, nodes: np.ndarray) -> float:
    """Yaw (rad) of a body about z from its rest shape to its current nodes (least squares)."""
    a = rest_vertices[:, :2] - rest_vertices[:, :2].mean(axis=0)
    b = nodes[:, :2] - nodes[:, :2].mean(axis=0)
    return float(np.arctan2((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum(), (a * b).sum()))


def draw_closure(card: dict | None, seed: int) -> float:
    """Closure for this episode: uniform in the calibrated envelope (seeded)."""
    if card is None:
        raise FileNotFoundError("the expert needs the object's calibration card; run python -m mani_skill_softvt.calibrate")
    rng = np.random.default_rng([seed, 7])
    return float(rng.uniform(card["g_min"], card["g_max"]))


def plan_pick_place(env, closure: float) -> ExpertPlan:
    """Waypoints for the instructed object of a :class:`SoftVTTaskEnv` that was just reset."""
    u = env.unwrapped
    name = u.target_instance
    nodes = u.soft_nodes(name)
    xy = nodes.mean(axis=0)[:2]
    height = nodes[:, 2].max() - nodes[:, 2].min()
    grasp_z = mid_height_grasp(nodes)
    yaw = _wrap_half_turn(object_yaw(u._specs[name].vertices, nodes))
    lo, hi = (np.asarray(v) for v in u.target_region)
    tgt = u.target.pose.p[0].cpu().numpy().astype(np.float64)
    drop_xy = tgt[:2] + 0.5 * (lo[:2] + hi[:2])
    # Release with the object's bottom just above the target floor (TCP at mid-object height).
    release_z = tgt[2] + lo[2] + RELEASE_CLEARANCE + (grasp_z - nodes[:, 2].min())
    g = float(closure)
    wp = [
        ("approach", [*xy, APPROACH_HEIGHT], 0.0),
        ("descend", [*xy, grasp_z], 0.0),
        ("close", [*xy, grasp_z], g),
        ("lift", [*xy, CARRY_HEIGHT], g),
        ("transport", [*drop_xy, CARRY_HEIGHT], g),
        ("lower", [*drop_xy, max(release_z, grasp_z)], g),
        ("release", [*drop_xy, max(release_z, grasp_z)], 0.0),
        ("retreat", [*drop_xy, CARRY_HEIGHT], 0.0),
        ("wait", [*drop_xy, CARRY_HEIGHT], 0.0),
    ]
    del height
    return ExpertPlan(g, [(p, np.asarray(t, np.float64), gg, yaw) for p, t, gg in wp])


def _wrap_half_turn(yaw: float) -> float:
    """The gripper is symmetric under a half turn: use the equivalent yaw closest to zero."""
    return float((yaw + np.pi / 2) % np.pi - np.pi / 2)


def expert_actions(env, plan: ExpertPlan):
    """Yield pd_ee_pose actions along the plan (straight lines, reaching each waypoint 2 steps early)."""
    u = env.unwrapped
    tcp = u.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64)
    for phase, target, g, yaw in plan.waypoints:
        n = PHASE_STEPS[phase]
        start = tcp.copy()
        for i in range(n):
            a = min(1.0, (i + 1) / max(1, n - 2))
            yield phase, ee_action(start + (target - start) * a, g, yaw)
        tcp = target


def run_expert(env, closure: float, on_step=None) -> dict:
    """Run the expert to the end of its plan or until the episode ends; return a summary."""
    plan = plan_pick_place(env, closure)
    info, steps = {}, 0
    for phase, action in expert_actions(env, plan):
        _, _, terminated, truncated, info = env.step(action)
        steps += 1
        if on_step is not None:
            on_step(phase, action, info)
        if bool(terminated[0]) or bool(truncated[0]):
            break
    return {"steps": steps, "closure": closure, "success": bool(info.get("success", [False])[0]),
            "dropped": bool(info.get("dropped", [False])[0])}


TOTAL_STEPS = sum(PHASE_STEPS.values())
assert TOTAL_STEPS < C.MAX_EPISODE_STEPS
