"""Scripted pick-and-place expert for the four suites (privileged: reads the object's state).

Waypoints: approach above the instructed object, descend to mid-height, close to the episode's
closure, lift, transport above the target, lower, release, retreat, and wait for the object to
settle. The closure is drawn per episode from the object's calibrated envelope [g_min, g_max]
(rigid twins use their soft asset's card). Two planners join the waypoints, both emitting
``pd_ee_pose`` actions (absolute TCP pose in the robot base frame, closure):

- ``"mplib"``: collision-free joint paths in ManiSkill's motion-planning style (screw motion,
  TOPP-RA at 20 Hz; RRTConnect is opt-in, being unseeded in mplib 0.1.1) around the table, the basket/plate and the other
  instance, each joint sample turned into its TCP pose by forward kinematics
  (:mod:`mani_skill_softvt.expert.planner`);
- ``"cartesian"``: straight lines between the waypoints, tracked by the controller's IK.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ..physics.transforms import down_quat_yaw, down_rotvec, quat_to_rotvec, yaw_between
from ..tasks import constants as C
from ..tasks.robot import ee_action, mid_height_grasp

PHASE_STEPS = {"approach": 15, "descend": 15, "close": 12, "lift": 15, "transport": 25, "lower": 15,
               "release": 8, "retreat": 10, "wait": 10}
APPROACH_HEIGHT = 0.12  # m above the table (TCP)
CARRY_HEIGHT = 0.16  # m: clears the basket rim (6 cm) with the object hanging below the TCP
RELEASE_CLEARANCE = 0.015  # m between the object's bottom and the target floor at release


PLANNERS = ("mplib", "cartesian")
DEFAULT_PLANNER = "mplib"


@dataclass
class ExpertPlan:
    closure: float
    waypoints: list = field(default_factory=list)  # [(phase, tcp xyz, gripper closure, yaw), ...]
    planner: str = "cartesian"  # the planner that produced this plan
    # mplib: [(phase, TCP poses (n, 7) xyz + wxyz in the robot base frame, gripper closure, method), ...]
    segments: list = field(default_factory=list)
    fallback_reason: str | None = None  # why an mplib request fell back to the Cartesian plan


def draw_closure(card, seed: int) -> float:
    """Closure for this episode: uniform in the calibrated envelope of ``card`` (a
    :class:`~mani_skill_softvt.calibration.cards.CalibrationCard`), seeded by the episode seed."""
    rng = np.random.default_rng([seed, 7])
    return float(rng.uniform(card.g_min, card.g_max))


def plan_pick_place(env, closure: float, planner: str = DEFAULT_PLANNER, strict: bool = False) -> ExpertPlan:
    """Plan for the instructed object of a :class:`SoftVTTaskEnv` that was just reset.

    When mplib finds no collision-free path for a phase the plan falls back to the Cartesian
    one (``plan.planner`` says which planner produced it, ``plan.fallback_reason`` why), or,
    with ``strict``, raises :class:`~mani_skill_softvt.expert.planner.PlanningError`.
    """
    if planner not in PLANNERS:
        raise ValueError(f"unknown expert planner '{planner}'; choose one of {PLANNERS}")
    u = env.unwrapped
    name = u.target_instance
    nodes = u.soft_nodes(name)
    xy = nodes.mean(axis=0)[:2]
    grasp_z = mid_height_grasp(nodes)
    yaw = _wrap_half_turn(yaw_between(u.rest_vertices(name), nodes))
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
    plan = ExpertPlan(g, [(p, np.asarray(t, np.float64), gg, yaw) for p, t, gg in wp], planner)
    if planner == "mplib":
        from .planner import PlanningError, held_object, plan_expert_path

        held = held_object(nodes, [*xy, grasp_z], yaw)
        try:
            segments = [(phase, seg.poses, gg, seg.method)
                        for phase, seg, gg in plan_expert_path(env, plan.waypoints, PHASE_STEPS, held)]
            steps = sum(len(poses) for _, poses, _, _ in segments)
            if steps >= C.MAX_EPISODE_STEPS:
                raise PlanningError(f"the plan takes {steps} control steps, an episode at most {C.MAX_EPISODE_STEPS}")
        except PlanningError as e:
            if strict:
                raise
            warnings.warn(f"mplib expert plan failed, using the Cartesian plan: {e}", stacklevel=2)
            plan.planner, plan.fallback_reason = "cartesian", str(e)
        else:
            plan.segments = segments
    return plan


def _wrap_half_turn(yaw: float) -> float:
    """The gripper is symmetric under a half turn: use the equivalent yaw closest to zero."""
    return float((yaw + np.pi / 2) % np.pi - np.pi / 2)


def expert_actions(env, plan: ExpertPlan):
    """Yield ``(phase, pd_ee_pose action)`` along the plan, reaching each waypoint 2 steps early.

    mplib plans replay their TCP poses; Cartesian plans move in straight lines.
    """
    if plan.planner == "mplib":
        for phase, poses, g, _ in plan.segments:
            for pose in poses:
                # Of the two axis-angles of a near-top-down hand, the one next to the Cartesian
                # expert's pi * (cos yaw, sin yaw, 0): the action stream stays continuous.
                ref = down_rotvec(down_quat_yaw(pose[3:]))
                rotvec = quat_to_rotvec(pose[3:], reference=ref)
                yield phase, np.concatenate([pose[:3], rotvec, [g]]).astype(np.float32)
        return
    u = env.unwrapped
    tcp = u.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64)
    for phase, target, g, yaw in plan.waypoints:
        n = PHASE_STEPS[phase]
        start = tcp.copy()
        for i in range(n):
            a = min(1.0, (i + 1) / max(1, n - 2))
            yield phase, ee_action(start + (target - start) * a, g, yaw)
        tcp = target


def run_expert(env, closure: float, on_step=None, planner: str = DEFAULT_PLANNER) -> dict:
    """Run the expert to the end of its plan or until the episode ends; return a summary."""
    plan = plan_pick_place(env, closure, planner)
    info, steps = {}, 0
    for phase, action in expert_actions(env, plan):
        _, _, terminated, truncated, info = env.step(action)
        steps += 1
        if on_step is not None:
            on_step(phase, action, info)
        if bool(terminated[0]) or bool(truncated[0]):
            break
    return {"steps": steps, "closure": closure, "planner": plan.planner,
            "success": bool(info.get("success", [False])[0]), "dropped": bool(info.get("dropped", [False])[0])}


TOTAL_STEPS = sum(PHASE_STEPS.values())
assert TOTAL_STEPS < C.MAX_EPISODE_STEPS
