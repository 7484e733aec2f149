"""The scripted expert as a ManiSkill motion-planning solution.

``solve(env, seed=None, debug=False, vis=False)`` has the signature of the solutions in
``mani_skill.examples.motionplanning.panda.solutions``: it resets ``env`` with ``seed``, runs the
plan and returns the last ``env.step`` result (its ``[-1]`` is the info with ``success`` and
``elapsed_steps``), or -1 when no plan was found, as ManiSkill's runner expects. The plan runs to
its end (the object released and at rest), not only to the first step that succeeds; where its
wait ends with the released object still moving in the target, the expert holds its last pose
until the object rests, at most :data:`SETTLE_STEPS` ticks (:func:`settle`). One solution
serves all four suites (the task is one parametrised class).

The plan is :func:`~mani_skill_softvt.expert.pick_place.plan_pick_place`: waypoints around the
instructed object joined by mplib joint paths, the closure drawn from the object's calibrated
envelope [g_min, g_max] with the episode seed. ManiSkill's ``PandaArmMotionPlanningSolver`` is
not used: it drives a fixed open/closed gripper command (+1 / -1), while a SoftVT grasp closes to
a calibrated closure in [0, 1] and plans around the soft object's hull and the other instance.
The env's control mode picks the action: ``pd_joint_pos`` (the planner's joint path, ManiSkill's
motion-planning format) or ``pd_ee_pose`` (the paper's absolute TCP pose), either ``_binary``.
"""

from __future__ import annotations

import numpy as np

from ..contracts.observations import info_bool
from ..contracts.policy import Policy
from ..rollout import Observer, rollout
from .pick_place import DEFAULT_PLANNER
from .planner import PlanningError
from .policy import ScriptedExpertPolicy


# At most this many more ticks (20 Hz) holding the plan's last pose when its wait ends with the
# released object still moving in its target (pastry010 rocks on the plate or in the basket after
# the release on some seeds), so that the demo ends at rest rather than being rejected.
SETTLE_STEPS = 20

SOURCE_DESC = ("mani_skill_softvt scripted expert (mani_skill_softvt.expert.solution.solve): mplib joint paths "
               "around the table, target and other instance (Cartesian fallback); gripper closure drawn from the "
               "object's calibrated envelope [g_min, g_max]")


def solve(env, seed=None, debug=False, vis=False, *, closure: float | None = None, planner: str = DEFAULT_PLANNER,
          strict: bool = False):
    """ManiSkill motion-planning solution of a SoftVT task (module docstring): a rollout of the
    scripted expert (:class:`~mani_skill_softvt.expert.policy.ScriptedExpertPolicy`) to the end of
    its plan.

    ``closure``: the gripper closure (default: drawn from the card's envelope with ``seed``);
    ``planner``: "mplib" (falls back to the Cartesian plan where mplib finds no path, unless
    ``strict``) or "cartesian". The closure and the planner that produced the plan go to the
    recorder's episode metadata when ``env`` is a :class:`~mani_skill_softvt.data.record.SoftVTRecordEpisode`.
    """
    class Show(Observer):
        def on_step(self, env, action, obs, info):
            env.unwrapped.render_human()

    class LastAction(Observer):
        action = None

        def on_step(self, env, action, obs, info):
            self.action = action

    # One action per call: an expert that fails mid-plan (IK of a Cartesian plan in joint space) has
    # stepped every action before the failure, as a solution stepping its plan does.
    expert = ScriptedExpertPolicy(chunk=1, planner=planner, closure=closure, strict=strict)
    # As ManiSkill's solutions do, the plan runs to its end past the first success (release,
    # retreat, wait): a replay converted into another control mode lags the original by a few
    # ticks, and must still end at rest in the target. A failure (a drop) or the time limit ends it.
    last = LastAction()
    shown = [Show()] if vis else []
    episode = rollout(env, expert, seed, replan_steps=1, until="plan", observers=[last, *shown])
    info = episode.info
    if episode.termination == "plan_end" and info_bool(info, "in_target") and not info_bool(info, "is_grasped") \
            and not info_bool(info, "success"):  # released in the target, not yet at rest
        episode = settle(env, last.action, seed, shown) or episode
    metadata = getattr(env, "episode_metadata", None)
    if metadata is not None and expert.plan is not None:  # whatever happened after planning
        metadata.update(closure=float(expert.closure), planner=expert.plan.planner)
    if isinstance(episode.exception, PlanningError) and episode.failed_in == "policy.reset()":
        if debug:
            print(f"no motion plan for seed {seed}: {episode.exception}")
        return -1
    if episode.exception is not None:  # the simulation or the expert itself failed: not a result here
        raise episode.exception
    return episode.last_step


class _Held(Policy):
    """The plan's last action, held (the pose of its wait, the hand open)."""

    name = "scripted_expert_settle"

    def __init__(self, action):
        self.action = np.asarray(action)

    def reset(self, instruction: str, seed: int) -> None:
        pass

    def act(self, obs) -> np.ndarray:
        return self.action[None]


def settle(env, action, seed, observers=()):
    """Hold ``action`` until the env's episode ends (the object at rest in its target: success) or
    :data:`SETTLE_STEPS` ticks pass; the rollout of those ticks (None without an action to hold).
    Only plans whose wait ended with the released object in its target but still moving get here: an episode that ended at rest
    is the same episode as before this existed, bit for bit."""
    if action is None:
        return None

    class Budget(Observer):
        ticks = 0

        def on_step(self, env, action, obs, info):
            self.ticks += 1
            return self.ticks >= SETTLE_STEPS

    more = rollout(env, _Held(action), seed, reset=False, replan_steps=1, until="episode",
                   observers=[Budget(), *observers])
    return more if more.last_step is not None else None
