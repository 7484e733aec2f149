"""A scripted top-down grasp, lift, hold and place, in absolute end-effector pose actions.

The calibration trial (grasp, lift, hold: :mod:`.sweep`), the grasp demo, the tactile gallery and
the physics tests use it: it drives any :class:`~mani_skill_softvt.tasks.SoftBodyEnv` whose
control mode is ``pd_ee_pose`` and records, per control step, the evaluator-side quantities (D_t,
jaw width, object height, pad force) that those consumers score.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..tasks.robot import ee_action, mid_height_grasp

@dataclass
class GraspPlan:
    """Heights are of the tool centre point above the table (m); durations in control steps."""

    grasp_height: float | None = None  # None: mid-height of the object (pads centred on it)
    approach_height: float = 0.12
    lift_height: float = 0.125
    closure: float = 1.0  # gripper closure while grasping (1 = close until the force limit)
    yaw: float = 0.0
    steps: dict = field(default_factory=lambda: {
        "approach": 20, "descend": 20, "close": 20, "lift": 30, "hold": 40, "lower": 30, "open": 10, "retreat": 15,
    })

    def phases(self, xy: np.ndarray, grasp_height: float):
        lo = np.array([*xy, grasp_height])
        hi = np.array([*xy, self.approach_height])
        up = np.array([*xy, self.lift_height])
        g_open, g_closed = 0.0, self.closure
        return [
            ("approach", hi, g_open), ("descend", lo, g_open), ("close", lo, g_closed), ("lift", up, g_closed),
            ("hold", up, g_closed), ("lower", lo, g_closed), ("open", lo, g_open), ("retreat", hi, g_open),
        ]


def run_grasp_script(env, plan: GraspPlan | None = None, object_name: str | None = None, on_step=None,
                     xy_offset=(0.0, 0.0)) -> dict:
    """Execute the script on an env that was just reset; return per-step records (numpy arrays).

    ``on_step(phase, i, n)`` is called after every control step; returning ``"stop"`` ends the
    script early (e.g. a calibration trial whose object was not lifted).
    """
    u = env.unwrapped
    plan = plan or GraspPlan()
    nodes = u.soft_nodes(object_name)
    xy = nodes.mean(axis=0)[:2] + np.asarray(xy_offset, np.float64)
    grasp_height = plan.grasp_height if plan.grasp_height is not None else mid_height_grasp(nodes)
    tcp = u.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64)
    rec = {k: [] for k in ("phase", "deformation", "gripper_width", "object_min_z", "object_centroid", "tcp",
                           "tcp_quat", "pad_force")}
    stop = False
    for phase, target, g in plan.phases(xy, grasp_height):
        n = plan.steps.get(phase, 0)
        start = tcp.copy()
        for i in range(n):
            a = min(1.0, (i + 1) / max(1, n - 2))  # reach the waypoint two steps early, then settle
            tcp_cmd = start + (target - start) * a
            env.step(ee_action(tcp_cmd, g, plan.yaw))
            nodes = u.soft_nodes(object_name)
            rec["phase"].append(phase)
            rec["deformation"].append(u.deformation(object_name))
            rec["gripper_width"].append(u.gripper_width)
            rec["object_min_z"].append(float(nodes[:, 2].min()))
            rec["object_centroid"].append(nodes.mean(axis=0))
            rec["tcp"].append(u.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64))
            rec["tcp_quat"].append(u.agent.tcp.pose.q[0].cpu().numpy().astype(np.float64))
            rec["pad_force"].append(u.pad_forces()["left"])
            if on_step is not None and on_step(phase, i, n) == "stop":
                stop = True
                break
        if stop:
            break
        tcp = target
    return {k: np.asarray(v) for k, v in rec.items()}
