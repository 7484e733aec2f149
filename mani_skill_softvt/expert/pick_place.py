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

from ..physics.transforms import down_quat_yaw, down_rotvec, quat_to_rotvec, rotvec_to_quat, yaw_between
from ..tasks import constants as C
from ..contracts.actions import ee_action, gripper_action, normalized_gripper
from ..tasks.robot import mid_height_grasp
from .planner import MotionPlanner, PlanningError, held_object, plan_expert_path

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
    # mplib: [(phase, Segment (arm joints (n, 7) and their TCP poses in the robot base frame), gripper closure), ...]
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
        held = held_object(nodes, [*xy, grasp_z], yaw)
        try:
            segments = plan_expert_path(env, plan.waypoints, PHASE_STEPS, held)
            steps = sum(len(seg.qpos) for _, seg, _ in segments)
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
        for phase, seg, g in plan.segments:
            for pose in seg.poses:
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


def joint_actions(env, plan: ExpertPlan):
    """Yield ``(phase, pd_joint_pos action)``: arm joint targets (7) and the gripper closure.

    mplib plans are joint paths already (what ManiSkill's motion-planning solutions send); a
    Cartesian plan's TCP targets are solved by IK along the way, each seeded by the last.
    """
    if plan.planner == "mplib":
        for phase, seg, g in plan.segments:
            for q in seg.qpos:
                yield phase, np.concatenate([q, [g]]).astype(np.float32)
        return

    mp = MotionPlanner(env)
    q = env.unwrapped.agent.robot.get_qpos()[0].cpu().numpy().astype(np.float64)[mp.arm]
    for phase, action in expert_actions(env, plan):
        pose_world = np.concatenate([action[:3].astype(np.float64) + C.ROBOT_BASE_POSE[:3],
                                     rotvec_to_quat(action[3:6].astype(np.float64))])
        q = mp.ik_path(q, mp.world_to_base(pose_world)[None])[0]
        yield phase, np.concatenate([q, [action[6]]]).astype(np.float32)


def mode_actions(env, plan: ExpertPlan):
    """Yield ``(phase, action)`` in the env's control mode: ``pd_ee_pose`` or ``pd_joint_pos``, or
    either's ``_binary`` twin (any commanded closure is "close"), the gripper in the mode's encoding
    (:func:`~mani_skill_softvt.contracts.actions.gripper_action`: the closure in ``pd_ee_pose``, ManiSkill's
    normalised action in ``pd_joint_pos``)."""
    mode = env.unwrapped.control_mode
    arm = mode.removesuffix("_binary")
    if arm not in ("pd_ee_pose", "pd_joint_pos"):
        raise ValueError(f"the scripted expert drives pd_ee_pose or pd_joint_pos (and their _binary modes), not "
                         f"'{mode}': record in pd_joint_pos and convert with `python -m mani_skill_softvt.integrations.maniskill.replay "
                         f"--traj-path FILE -c {mode}`")
    actions = expert_actions(env, plan) if arm == "pd_ee_pose" else joint_actions(env, plan)
    normalized = normalized_gripper(mode)
    for phase, action in actions:
        if normalized:
            action = action.copy()
            action[-1] = gripper_action(action[-1], mode)
        elif mode.endswith("_binary"):
            action = action.copy()
            action[-1] = np.float32(action[-1] > 0.0)
        yield phase, action


TOTAL_STEPS = sum(PHASE_STEPS.values())
assert TOTAL_STEPS < C.MAX_EPISODE_STEPS
