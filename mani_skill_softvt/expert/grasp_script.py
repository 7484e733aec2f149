"""A scripted top-down grasp, lift, hold and place, in absolute end-effector pose actions.

The calibration trial (grasp, lift, hold: :func:`mani_skill_softvt.expert.calibration_trials.run_trial`), the grasp demo, the tactile gallery and
the physics tests use it: it drives any :class:`~mani_skill_softvt.tasks.SoftBodyEnv` whose
control mode is ``pd_ee_pose`` and records, per control step, the evaluator-side quantities (D_t,
jaw width, object height, pad force) that those consumers score.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..physics.constants import MIN_TET_VOLUME_RATIO
from ..physics.errors import SimulationInstabilityError
from ..contracts.policy import Policy
from ..rollout import EvaluatorTrace, Observer, rollout
from ..contracts.actions import ee_action
from ..tasks.robot import mid_height_grasp

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


class GraspScriptPolicy(Policy):
    """The script as a privileged policy: at ``reset`` it reads where the object rests (its
    centroid, plus ``xy_offset``; the pads at its mid-height unless the plan says) and where the
    TCP is, then hands out the phases' actions in order; ``phase_of(k)`` names the k-th action's
    phase, its index in the phase and the phase's length."""

    name = "grasp_script"
    privileged = True

    def __init__(self, plan: GraspPlan, object_name: str | None = None, xy_offset=(0.0, 0.0), chunk: int = 8):
        self.plan, self.object_name, self.xy_offset, self.chunk = plan, object_name, xy_offset, chunk
        self.env = None

    def bind(self, env) -> None:
        self.env = env

    def reset(self, instruction: str, seed) -> None:
        u = self.env.unwrapped
        plan = self.plan
        nodes = u.soft_nodes(self.object_name)
        xy = nodes.mean(axis=0)[:2] + np.asarray(self.xy_offset, np.float64)
        grasp_height = plan.grasp_height if plan.grasp_height is not None else mid_height_grasp(nodes)
        tcp = u.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64)
        self.steps, self.actions = [], []
        for phase, target, g in plan.phases(xy, grasp_height):
            n = plan.steps.get(phase, 0)
            start = tcp.copy()
            for i in range(n):
                a = min(1.0, (i + 1) / max(1, n - 2))  # reach the waypoint two steps early, then settle
                self.steps.append((phase, i, n))
                self.actions.append(ee_action(start + (target - start) * a, g, plan.yaw))
            tcp = target
        self._k = 0

    @property
    def done(self) -> bool:
        return self._k >= len(self.actions)

    def phase_of(self, k: int) -> tuple[str, int, int]:
        return self.steps[k]

    def act(self, obs) -> np.ndarray:
        out = self.actions[self._k:self._k + self.chunk]
        self._k += len(out)
        return np.stack(out)


def run_grasp_script(env, plan: GraspPlan | None = None, object_name: str | None = None, on_step=None,
                     xy_offset=(0.0, 0.0)) -> dict:
    """Execute the script on an env that was just reset (a rollout of :class:`GraspScriptPolicy`
    to its end); return per-step records (numpy arrays) from the evaluator trace.

    ``on_step(phase, i, n)`` is called after every control step; returning ``"stop"`` ends the
    script early (e.g. a calibration trial whose object was not lifted). A collapsed tet raises
    :class:`~mani_skill_softvt.physics.errors.SimulationInstabilityError`: a grasp the calibration
    measures must keep the mesh valid throughout (its peak D would not be trustworthy).
    """
    object_name = object_name or env.unwrapped.object_names[0]  # the scene's first object unless named
    script = GraspScriptPolicy(plan or GraspPlan(), object_name, xy_offset)
    trace = EvaluatorTrace(object_name)
    phases = []

    class Phases(Observer):
        def on_step(self, env, action, obs, info):
            phases.append(script.phase_of(len(phases)))
            return on_step is not None and on_step(*phases[-1]) == "stop"

    episode = rollout(env, script, reset=False, observers=[trace, Phases()], until="script")
    if episode.exception is not None:
        raise episode.exception
    t = trace.arrays()
    if t["collapsed_tets"].any():
        k = int(np.argmax(t["collapsed_tets"] > 0))
        raise SimulationInstabilityError(f"{int(t['collapsed_tets'][k])} tets collapsed (volume <= {MIN_TET_VOLUME_RATIO} x "
                                         f"rest) at state {k} of the grasp script on '{object_name}'")
    return {"phase": np.asarray([p for p, _, _ in phases]), "deformation": t["deformation"],
            "gripper_width": t["gripper_width"], "object_min_z": t["object_min_z"],
            "object_centroid": t["object_centroid"], "tcp": t["tcp"], "tcp_quat": t["tcp_quat"],
            "pad_force": t["pad_force"][:, 0]}
