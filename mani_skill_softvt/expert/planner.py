"""Joint-space motion planning for the scripted expert (mplib), emitted as end-effector pose targets.

The expert's waypoints (approach, descend, lift, transport, lower, retreat) are joined by
collision-free joint paths in ManiSkill's motion-planning style: a screw motion first
(:meth:`mplib.Planner.plan_screw`), an RRTConnect path (:meth:`mplib.Planner.plan_qpos_to_pose`)
when the screw collides, both time-parametrised (TOPP-RA) at the 20 Hz control rate. Each joint
sample is turned back into a TCP pose by mplib's forward kinematics (pinocchio), so the env is
still driven with ``pd_ee_pose`` actions and the recorded demos keep that action space.

The planning scene holds the static geometry only: the table top, the target prop (basket or
plate, its convex parts) and every soft instance except the one being grasped (convex hull of its
nodes). While the object is held it rides along as a box attached to the TCP.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from ..assets import load_prop
from ..physics.transforms import down_quat, quat_angle, quat_conjugate, quat_multiply, quat_wxyz_to_matrix
from ..tasks import constants as C

CONTROL_DT = 1.0 / C.CONTROL_FREQ
# TOPP limits (rad/s, rad/s^2) of ManiSkill's Panda motion-planning solutions.
JOINT_VEL_LIMIT = 0.9
JOINT_ACC_LIMIT = 0.9
SCREW_STEP = 0.02  # rad: joint step of the screw path (each step is collision-checked)
RRT_TIME = 1.0  # s: RRTConnect time budget per try
# RRTConnect tries after the screw paths fail. Off by default: mplib 0.1.1 exposes no seed for
# OMPL, so an RRT path differs run to run and the expert would no longer be bit-reproducible;
# the expert falls back to its (deterministic) Cartesian plan instead. Opt in per planner.
RRT_TRIES = 0
RRT_RANGE = 0.05  # rad: RRT step (denser waypoints keep the smoothed path near the validated one)
# The planning table's top sits this far below the real one: the robot's base link rests on the
# table (zero clearance would read as a collision), and the lowest grasp keeps its fingertips
# 2.75 mm above the top (C.MIN_GRASP_HEIGHT), so this still counts as a margin.
TABLE_TOP_MARGIN = 1e-3
OPEN_FINGER_Q = C.GRIPPER_Q_OPEN
TCP_LINK = "panda_hand_tcp"
# Tolerances of a planned segment's end pose against its goal.
GOAL_POS_TOL = 3e-3  # m
GOAL_ROT_TOL = np.deg2rad(2.0)  # rad


class PlanningError(RuntimeError):
    """No collision-free joint path reaches the requested TCP pose."""


# mplib 0.1.1, the version ManiSkill 3.0.1 pins, dies with SIGSEGV building its planner under NumPy 2
# (the LeRobot stack, docs/install.md). Refusing it there turns a crash of the whole process into a
# PlanningError: the expert then takes its Cartesian plan (its receipt says so), and strict callers
# get the reason.
MPLIB_PLANS = int(np.__version__.split(".")[0]) < 2
MPLIB_UNAVAILABLE = (f"mplib 0.1.1 (pinned by ManiSkill 3.0.1) crashes planning under NumPy {np.__version__}: its "
                     "motion plans need the default stack (scripts/setup.sh, NumPy 1.26)")


@dataclass
class Obstacle:
    """A convex collision body of the planning scene, vertices in the world frame."""

    name: str
    vertices: np.ndarray  # (N, 3)
    faces: np.ndarray  # (M, 3) triangles, outward or not (fcl builds the convex from them)


@dataclass
class Segment:
    """A planned motion: arm joint samples at the control rate and their TCP poses (base frame)."""

    qpos: np.ndarray  # (n, 7)
    poses: np.ndarray  # (n, 7): xyz, quaternion wxyz, in the robot base frame
    method: str  # "screw", "rrt" or "hold" (no motion)


def box_obstacle(name: str, lo, hi) -> Obstacle:
    """An axis-aligned box obstacle between the world-frame corners ``lo`` and ``hi``."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    v = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return Obstacle(name, v, f)


def _halfspaces(points: np.ndarray):
    """(A, b) with the convex hull of ``points`` = {x : A x <= b}."""
    eq = ConvexHull(points).equations  # rows (n, d): n . x + d <= 0 inside
    return eq[:, :3], -eq[:, 3]


def _hull(points: np.ndarray):
    h = ConvexHull(points)
    used = np.unique(h.simplices)
    remap = -np.ones(len(points), np.int64)
    remap[used] = np.arange(len(used))
    return points[used], remap[h.simplices]


# ---------------------------------------------------------------- scene
def scene_obstacles(env, exclude=None) -> list[Obstacle]:
    """Static collision geometry of a reset :class:`SoftVTTaskEnv` (world frame).

    The table top, the target prop's convex parts at its current pose, and the convex hull of
    every soft instance but ``exclude`` (default: the instructed one, which the gripper grasps).
    """
    u = env.unwrapped
    exclude = u.target_instance if exclude is None else exclude
    he = np.asarray(C.TABLE_HALF_EXTENTS)
    top = -TABLE_TOP_MARGIN
    obstacles = [box_obstacle("table", [-he[0], -he[1], top - 2 * he[2]], [he[0], he[1], top])]
    pose = u.target.pose.raw_pose[0].cpu().numpy().astype(np.float64)
    rot, p = quat_wxyz_to_matrix(pose[3:]), pose[:3]
    for i, (v, f) in enumerate(load_prop(u.task.target).convex_parts()):
        obstacles.append(Obstacle(f"{u.task.target}_{i:02d}", np.asarray(v) @ rot.T + p, np.asarray(f)))
    for name in u.object_names:
        if name != exclude:
            obstacles.append(Obstacle(f"soft_{name}", *_hull(u.soft_nodes(name).astype(np.float64))))
    return obstacles


# ---------------------------------------------------------------- planner
class MotionPlanner:
    """mplib planner for the SoftVT Panda (ManiSkill's URDF/SRDF) placed at the env's robot base."""

    def __init__(self, env, joint_vel_limit: float = JOINT_VEL_LIMIT, joint_acc_limit: float = JOINT_ACC_LIMIT,
                 rrt_tries: int = RRT_TRIES):
        if not MPLIB_PLANS:
            raise PlanningError(MPLIB_UNAVAILABLE)
        import mplib  # here, not at the top: under NumPy 2 importing it can crash the process (MPLIB_PLANS)

        self.rrt_tries = int(rrt_tries)
        u = env.unwrapped
        robot = u.agent.robot
        urdf = u.agent.urdf_path
        srdf = urdf.replace(".urdf", ".srdf")
        for path in (urdf, srdf):
            if not os.path.exists(path):
                raise FileNotFoundError(f"the motion planner needs the robot description {path}")
        self.link_names = [link.get_name() for link in robot.get_links()]
        self.joint_names = [j.get_name() for j in robot.get_active_joints()]
        with contextlib.redirect_stdout(io.StringIO()):
            self.mp = mplib.Planner(urdf=urdf, srdf=srdf, user_link_names=self.link_names,
                                    user_joint_names=self.joint_names, move_group=TCP_LINK,
                                    joint_vel_limits=np.full(7, joint_vel_limit),
                                    joint_acc_limits=np.full(7, joint_acc_limit))
        self.base_pose = robot.pose.raw_pose[0].cpu().numpy().astype(np.float64)
        self.mp.set_base_pose(self.base_pose)
        self.tcp_index = self.mp.link_name_2_idx[TCP_LINK]
        self.arm = np.asarray(self.mp.move_group_joint_indices)
        self.joint_limits = np.asarray(self.mp.joint_limits)  # (9, 2)
        self.obstacles: list[Obstacle] = []
        self._hulls: list = []  # (name, (A, b)): the obstacle is {x : A x <= b}
        self.finger_q = OPEN_FINGER_Q
        self._attached = False

    # -------------------------------------------------------- scene
    def set_obstacles(self, obstacles: list[Obstacle]) -> None:
        from mplib.pymp.collision_detection import fcl  # mplib: imported only where it plans (above)

        for name in self.mp.planning_world.get_normal_object_names():
            self.mp.remove_normal_object(name)
        self._hulls = []
        for ob in obstacles:
            with contextlib.suppress(Exception):  # a flat (degenerate) body has no interior to test
                self._hulls.append((ob.name, _halfspaces(ob.vertices)))
            geom = fcl.Convex(np.ascontiguousarray(ob.vertices, np.float64), np.ascontiguousarray(ob.faces, np.int32))
            self.mp.set_normal_object(ob.name, fcl.CollisionObject(geom, np.zeros(3), np.array([1.0, 0, 0, 0])))
        self.obstacles = list(obstacles)

    def attach_box(self, size, center_in_tcp) -> None:
        """Carry a box (full side lengths, in the TCP frame) with the hand: the held object."""
        self.mp.update_attached_box(np.asarray(size, np.float64), np.array([*center_in_tcp, 1.0, 0, 0, 0]))
        self._attached = True

    def detach(self) -> None:
        if self._attached:
            self.mp.planning_world.remove_attach()
        self._attached = False

    # -------------------------------------------------------- kinematics
    def full_qpos(self, arm_q, finger_q: float | None = None) -> np.ndarray:
        """Arm joints plus both finger joints (default: the fingers of the current plan)."""
        q = np.full(len(self.joint_names), self.finger_q if finger_q is None else finger_q, np.float64)
        q[self.arm] = np.asarray(arm_q, np.float64)[: len(self.arm)]
        return q

    def set_fingers(self, finger_q: float) -> None:
        """Finger joint position (half the jaw gap) assumed while planning the next segments."""
        self.finger_q = float(np.clip(finger_q, 0.0, C.GRIPPER_Q_OPEN))

    def free_finger_q(self, arm_q, wanted: float = C.GRIPPER_Q_OPEN, step: float = 1e-3) -> float:
        """The widest finger opening up to ``wanted`` that is collision-free at ``arm_q``: where an
        opening gripper ends up when the walls around it stop its fingers."""
        for q in np.arange(wanted, -1e-9, -step):
            if not self.collisions(arm_q, finger_q=q):
                return float(q)
        raise PlanningError(f"the hand is in collision at {np.round(self.fk(arm_q)[:3], 4).tolist()} even with closed "
                            f"fingers: {_fmt(self.collisions(arm_q, finger_q=0.0))}")

    def fk(self, arm_q) -> np.ndarray:
        """TCP pose (xyz, wxyz) in the robot base frame."""
        pm = self.mp.pinocchio_model
        pm.compute_forward_kinematics(self.full_qpos(arm_q))
        return np.asarray(pm.get_link_pose(self.tcp_index), np.float64)

    def ik_path(self, arm_q, poses_base) -> np.ndarray:
        """Arm joints reaching each TCP pose (xyz, wxyz; base frame) in turn, each solve seeded by the
        last (a Cartesian plan driven in joint space); raises :class:`PlanningError` where IK fails."""
        pm = self.mp.pinocchio_model
        q, out = np.asarray(arm_q, np.float64), []
        for pose in np.asarray(poses_base, np.float64):
            q_ik, ok, _ = pm.compute_IK_CLIK(self.tcp_index, pose, self.full_qpos(q), [])
            if not ok:
                raise PlanningError(f"no IK solution for the TCP pose {np.round(pose, 4).tolist()} (base frame)")
            q = np.asarray(q_ik, np.float64)[self.arm]
            out.append(q)
        return np.asarray(out)

    def base_to_world(self, pose) -> np.ndarray:
        rot = quat_wxyz_to_matrix(self.base_pose[3:])
        p = rot @ np.asarray(pose[:3]) + self.base_pose[:3]
        return np.concatenate([p, quat_multiply(self.base_pose[3:], pose[3:])])

    def world_to_base(self, pose) -> np.ndarray:
        rot = quat_wxyz_to_matrix(self.base_pose[3:])
        p = rot.T @ (np.asarray(pose[:3]) - self.base_pose[:3])
        return np.concatenate([p, quat_multiply(quat_conjugate(self.base_pose[3:]), pose[3:])])

    def collisions(self, arm_q, attached: bool | None = None, finger_q: float | None = None) -> list[tuple[str, str]]:
        """(robot link or attached object, obstacle or link) pairs in contact at ``arm_q``."""
        world = self.mp.planning_world
        use_attach = self._attached if attached is None else attached
        world.set_use_attach(use_attach)
        world.set_use_point_cloud(False)
        old = self.mp.robot.get_qpos()
        self.mp.robot.set_qpos(self.full_qpos(arm_q, finger_q), True)
        out = [(r.link_name1, r.object_name2 if r.object_name2 not in ("", "robot") else r.link_name2)
               for r in world.collide_full()]
        self.mp.robot.set_qpos(old, True)
        return out

    def within_limits(self, arm_q, tol: float = 1e-3) -> bool:
        lim = self.joint_limits[self.arm]
        q = np.asarray(arm_q)[: len(self.arm)]
        return bool(np.all(q >= lim[:, 0] - tol) and np.all(q <= lim[:, 1] + tol))

    # -------------------------------------------------------- planning
    def plan(self, arm_q, goal_pose_base, min_steps: int = 1) -> Segment:
        """Joint path from ``arm_q`` to the TCP ``goal_pose_base`` (xyz, wxyz; base frame).

        Screw motion first, RRTConnect if the screw collides; the path is sampled at the control
        rate (slowed down uniformly to at least ``min_steps`` samples; the start itself is not a
        sample), its end is refined onto the goal by IK, and every sample (and three points
        between consecutive samples) is checked for collisions and joint limits. Raises
        :class:`PlanningError` when no path passes.
        """
        goal = np.asarray(goal_pose_base, np.float64)
        tcp_world = self.base_to_world(goal)[:3]
        for name, (a, b) in self._hulls:
            if np.all(a @ tcp_world <= b):
                raise PlanningError(f"the goal TCP position {np.round(tcp_world, 4).tolist()} (world) lies inside "
                                    f"the obstacle '{name}'")
        q0 = self.full_qpos(arm_q)
        hits = self.collisions(q0[self.arm])
        if hits:
            raise PlanningError(f"start configuration in collision: {_fmt(hits)}")
        if self._at_goal(q0[self.arm], goal):
            return self.hold(q0[self.arm], max(1, min_steps))
        attempts = []
        # mplib's screw loop reports failure when its last step happens to be shorter than 0.1 mm:
        # a second screw with another step size sidesteps that before falling back to RRT.
        # RRT is randomised and its time-parametrised spline may cut a corner the tree avoided:
        # a few draws, each checked densely.
        tries = [("screw", lambda: self._screw(q0, goal, SCREW_STEP)),
                 ("screw", lambda: self._screw(q0, goal, SCREW_STEP * 0.93))]
        tries += [("rrt", lambda: self._rrt(q0, goal))] * self.rrt_tries
        for method, fn in tries:
            result = fn()
            if result["status"] != "Success":
                attempts.append(f"{method}: {result['status']}")
                continue
            qs = self._finish(q0[self.arm], np.asarray(result["position"], np.float64), goal, min_steps)
            problem = self.check_path(q0[self.arm], qs, goal)
            if problem is None:
                return Segment(qs, np.stack([self.fk(q) for q in qs]), method)
            attempts.append(f"{method}: {problem}")
        raise PlanningError(f"no collision-free path to TCP pose {np.round(goal, 4).tolist()} (base frame): "
                            f"{'; '.join(attempts)}{self._diagnose(q0, goal)}")

    def hold(self, arm_q, steps: int) -> Segment:
        qs = np.repeat(np.asarray(arm_q, np.float64)[None, : len(self.arm)], steps, axis=0)
        return Segment(qs, np.repeat(self.fk(qs[0])[None], steps, axis=0), "hold")

    def check_path(self, q_start, qs, goal=None, substeps: int = 4) -> str | None:
        """Why a joint path is not acceptable (None: it is): joint limits, collisions along the
        way (checked ``substeps`` times per control interval), end pose away from ``goal``."""
        prev = np.asarray(q_start, np.float64)[: len(self.arm)]
        for i, q in enumerate(qs):
            if not self.within_limits(q):
                return f"sample {i} outside the joint limits"
            for a in np.linspace(0.0, 1.0, substeps + 1)[1:]:
                hits = self.collisions(prev + a * (q - prev))
                if hits:
                    return f"sample {i} in collision ({_fmt(hits)})"
            prev = q
        if goal is not None and not self._at_goal(qs[-1], goal):
            end = self.fk(qs[-1])
            return (f"path ends {np.linalg.norm(end[:3] - goal[:3]) * 1e3:.1f} mm / "
                    f"{np.rad2deg(quat_angle(end[3:], goal[3:])):.1f} deg from the goal")
        return None

    def _at_goal(self, arm_q, goal) -> bool:
        end = self.fk(arm_q)
        close = np.linalg.norm(end[:3] - goal[:3]) <= GOAL_POS_TOL
        return bool(close and quat_angle(end[3:], goal[3:]) <= GOAL_ROT_TOL)

    def _finish(self, q_start, path, goal, min_steps) -> np.ndarray:
        """Path samples after the start, slowed to ``min_steps``, the end corrected onto the goal."""
        if np.linalg.norm(path[0] - q_start) > 1e-9:
            path = np.vstack([q_start[None], path])
        # The screw integrates the twist to first order (a few mm of drift): close the gap by IK and
        # spread the small correction along the path.
        pm = self.mp.pinocchio_model
        q_ik, ok, _ = pm.compute_IK_CLIK(self.tcp_index, goal, self.full_qpos(path[-1]), [])
        dq = np.asarray(q_ik, np.float64)[self.arm] - path[-1]
        if ok and np.abs(dq).max() < 0.05:
            path = path + np.linspace(0.0, 1.0, len(path))[:, None] * dq[None]
        return _resample(path, max(len(path) - 1, min_steps) + 1)[1:]

    def _screw(self, q0, goal, step: float):
        with contextlib.redirect_stdout(io.StringIO()), quiet_toppra():
            try:
                return self.mp.plan_screw(goal, q0.copy(), qpos_step=step, time_step=CONTROL_DT,
                                          use_attach=self._attached, wrt_world=False)
            except RuntimeError as e:  # TOPP-RA can fail on degenerate paths
                return {"status": f"screw plan failed ({e})"}

    def _rrt(self, q0, goal):
        with contextlib.redirect_stdout(io.StringIO()), quiet_toppra():
            try:
                return self.mp.plan_qpos_to_pose(goal, q0.copy(), time_step=CONTROL_DT, rrt_range=RRT_RANGE,
                                                 planning_time=RRT_TIME, use_attach=self._attached, wrt_world=False)
            except RuntimeError as e:
                return {"status": f"RRT failed ({e})"}

    def _diagnose(self, q0, goal) -> str:
        """Why the goal is unreachable: the colliding bodies of an IK solution, if any converges."""
        pm = self.mp.pinocchio_model
        q, ok, _ = pm.compute_IK_CLIK(self.tcp_index, goal, q0.copy(), [])
        q = np.asarray(q)
        pm.compute_forward_kinematics(q)
        end = np.asarray(pm.get_link_pose(self.tcp_index))
        if np.linalg.norm(end[:3] - goal[:3]) > GOAL_POS_TOL:
            return "; inverse kinematics from the start does not reach the pose (out of reach?)"
        hits = self.collisions(q[self.arm])
        return f"; the goal pose is in collision: {_fmt(hits)}" if hits else ""


@contextlib.contextmanager
def quiet_toppra():
    """Run an mplib planning call without TOPP-RA's console output.

    mplib calls ``toppra.setup_logging`` before every time parametrisation, which adds one more
    stderr handler to the ``toppra`` logger each time: after a few hundred plans every TOPP-RA
    warning prints hundreds of times between the progress bars. A failed parametrisation is
    already one of :meth:`MotionPlanner.plan`'s attempts (mplib raises it, the planner records it
    and says it in its :class:`PlanningError`), so the warning carries nothing. The ``toppra``
    loggers' handlers and levels are restored on exit; other loggers are untouched.
    """
    root = logging.getLogger("toppra")
    handlers, level = list(root.handlers), root.level
    children = [lg for name, lg in logging.Logger.manager.loggerDict.items()
                if name.startswith("toppra.") and isinstance(lg, logging.Logger)]
    levels = [lg.level for lg in children]
    for lg in children:
        lg.setLevel(logging.ERROR)  # mplib resets the parent's level inside the call, not the children's
    try:
        yield
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)
        for lg, lv in zip(children, levels):
            lg.setLevel(lv)


def _fmt(hits) -> str:
    return ", ".join(sorted({f"{a} with {b}" for a, b in hits}))


def _resample(qs: np.ndarray, n: int) -> np.ndarray:
    """Slow a time-parametrised path down uniformly to ``n`` samples (never speeds it up)."""
    if len(qs) >= n:
        return qs
    if len(qs) == 1:
        return np.repeat(qs, n, axis=0)
    t_old = np.linspace(0.0, 1.0, len(qs))
    t_new = np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(t_new, t_old, qs[:, j]) for j in range(qs.shape[1])], axis=1)


# ---------------------------------------------------------------- the expert's path
@dataclass
class HeldObject:
    """The grasped object as the planner carries it: a box between the pads, in the TCP frame."""

    size: np.ndarray  # full side lengths along the TCP frame's axes
    center: np.ndarray  # box centre in the TCP frame
    jaw_width: float  # object width between the pads (m)


def held_object(nodes: np.ndarray, grasp_xyz, yaw: float) -> HeldObject:
    """Box of an object's nodes in the frame of a top-down TCP at ``grasp_xyz`` turned by ``yaw``."""
    rot = quat_wxyz_to_matrix(down_quat(yaw))
    local = (np.asarray(nodes, np.float64) - np.asarray(grasp_xyz, np.float64)) @ rot  # rows: R^T (x - p)
    lo, hi = local.min(axis=0), local.max(axis=0)
    jaw = float(hi[1] - lo[1])  # the fingers close along the TCP's y axis
    # TCP z points down: trim the bottom (the object rests on the table at the grasp, its lowest
    # nodes may sag a hair into it) and keep the top clear of the finger roots and the hand.
    hi[2] -= 4e-3
    lo[2] = max(lo[2], -0.04)
    size = hi - lo
    size[1] = max(jaw - 2e-3, 1e-3)  # just inside the pads: the box never touches the fingers
    return HeldObject(size, 0.5 * (lo + hi), jaw)


def plan_expert_path(env, waypoints, phase_steps: dict, held: HeldObject, settle_steps: int = 2,
                     planner: MotionPlanner | None = None) -> list:
    """Joint-space plan of the expert's waypoints on a reset env.

    ``waypoints`` are ``(phase, tcp xyz (world), gripper closure, yaw)``. Each phase gets a
    planned motion of at least ``phase_steps[phase] - settle_steps`` samples and then
    ``settle_steps`` samples holding its end (the waypoint is reached early, as in the Cartesian
    expert); phases without motion (close, release) hold. While the gripper holds the object
    (a closure > 0 after a closing phase) it is planned closed on the object, with the object as
    an attached box; an open gripper is planned as wide as the surrounding walls let it open.
    Returns ``[(phase, Segment, closure), ...]``; raises :class:`PlanningError`.
    """
    u = env.unwrapped
    mp = planner or MotionPlanner(env)
    mp.set_obstacles(scene_obstacles(env))
    q = u.agent.robot.get_qpos()[0].cpu().numpy().astype(np.float64)
    mp.set_fingers(float(np.mean(q[-2:])))
    q = q[mp.arm]
    out, prev_g = [], 0.0
    for phase, target, g, yaw in waypoints:
        holding = g > 0 and prev_g > 0
        if holding:
            mp.set_fingers(held.jaw_width / 2)
            mp.attach_box(held.size, held.center)
        else:
            mp.detach()
            if g <= 0:
                mp.set_fingers(mp.free_finger_q(q))
        goal = mp.world_to_base(np.concatenate([np.asarray(target, np.float64), down_quat(yaw)]))
        n = int(phase_steps[phase])
        try:
            seg = mp.plan(q, goal, max(1, n - settle_steps))
        except PlanningError as e:
            raise PlanningError(f"{phase}: {e}") from e
        if settle_steps > 0:
            rest = mp.hold(seg.qpos[-1], settle_steps)
            seg = Segment(np.vstack([seg.qpos, rest.qpos]), np.vstack([seg.poses, rest.poses]), seg.method)
        out.append((phase, seg, float(g)))
        q, prev_g = seg.qpos[-1], g
    mp.detach()
    return out
