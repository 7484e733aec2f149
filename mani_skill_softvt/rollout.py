"""One rollout: an env, a policy, an episode, and the observers that watch it.

Every episode the package runs goes through :func:`rollout`: an evaluation episode
(:func:`mani_skill_softvt.evaluation.runner.run_episode`), an expert demonstration (the
motion-planning solution :func:`mani_skill_softvt.expert.solution.solve`, recorded by
:class:`~mani_skill_softvt.data.record.SoftVTRecordEpisode`) and a calibration trial
(:func:`mani_skill_softvt.expert.grasp_script.run_grasp_script`). They differ in the policy,
the observers, and what ends the episode (``until``):

- ``"episode"``: the env ends it, success or failure (terminated), or the time limit (evaluation);
- ``"plan"``: a scripted policy's plan runs to its end, past the first success, as ManiSkill's
  motion-planning solutions do; a failure (the object dropped) or the time limit ends it earlier;
- ``"script"``: the script's end, whatever the env reports (calibration trials).

An observer ends any rollout early by returning True from ``on_step``. The policy's own failures
never raise here: an exception in ``reset`` or ``act``, or malformed actions, end the episode as
``policy_error``, and a blow-up of the FEM as ``sim_unstable``; :attr:`Episode.exception` keeps
the exception for callers that raise it on (the expert's solution, a calibration trial).

What the evaluator watches, in one format for every consumer: :class:`EvaluatorTrace`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from mani_skill.utils.common import to_numpy

from .contracts.observations import as_bool, info_bool
from .physics.errors import SimulationInstabilityError
from .contracts.policy import is_privileged

UNTIL = ("episode", "plan", "script")
MAX_ERROR_CHARS = 2000


class Observer:
    """Watches a rollout: the state after the reset, then each step."""

    def on_reset(self, env, obs, info) -> None:
        pass

    def on_step(self, env, action, obs, info) -> bool | None:
        """After each step; True ends the rollout (termination ``stopped``)."""


@dataclass
class Episode:
    """How a rollout went."""

    steps: int = 0
    # success / dropped / timeout (the env's end), plan_end, stopped (an observer), sim_unstable, policy_error
    termination: str | None = None
    error: str | None = None  # the message of a policy_error or sim_unstable
    exception: BaseException | None = None
    failed_in: str | None = None  # "policy.reset()", "policy.act()" or "env.step()"
    privileged: bool = False  # the policy planned on the env
    obs: object = None  # the last observation and info (the reset's before any step)
    info: dict = field(default_factory=dict)
    last_step: tuple | None = None  # the last env.step result (what ManiSkill's solutions return)


def may_plan_on_env(policy) -> bool:
    """Only the package's own scripted policies read the simulator. A policy from outside the
    package that claims the privilege runs as what it is: observation-only."""
    return is_privileged(policy) and type(policy).__module__.startswith("mani_skill_softvt.")


def _error_text(e: BaseException, where: str) -> str:
    text = f"{type(e).__name__} in {where}: {e}"
    return text if len(text) <= MAX_ERROR_CHARS else text[:MAX_ERROR_CHARS] + " [...]"


def action_chunk(raw, env, replan_steps: int) -> list:
    """The actions of a chunk that will be executed, each validated by the env (numbers, shape, finite)."""
    chunk = np.asarray(to_numpy(raw)) if not isinstance(raw, (list, tuple)) else np.asarray(raw)
    if chunk.ndim == 1:
        chunk = chunk[None]
    if chunk.ndim != 2 or len(chunk) == 0:
        raise ValueError(f"act() must return an action (7,) or a chunk (k, 7) with k >= 1, got shape {chunk.shape}")
    return [env.validate_action(a) for a in chunk[:replan_steps]]


def episode_end(until: str, terminated, truncated, info) -> str | None:
    """How a step ended the rollout (``success``, ``dropped``, ``timeout``), or None if it goes on."""
    if until == "episode" and (as_bool(terminated) or as_bool(truncated)):
        return "success" if info_bool(info, "success") else "dropped" if info_bool(info, "dropped") else "timeout"
    if until == "plan" and (as_bool(truncated) or info_bool(info, "fail")):
        return "dropped" if info_bool(info, "fail") else "timeout"
    return None


def rollout(env, policy, seed: int | None = None, *, options: dict | None = None, reset: bool = True,
            replan_steps: int = 8, observers=(), until: str = "episode", skip_unread_cameras: bool = False) -> Episode:
    """Run ``policy`` on ``env`` for one episode (module docstring).

    ``reset=False`` continues an env its caller has just reset (and ``seed`` is then only what
    the policy's ``reset`` is told). A policy that can finish (``done`` true: its plan or script
    is exhausted) ends ``"plan"`` and ``"script"`` rollouts as ``plan_end``; under ``"episode"``
    it is asked again.

    ``skip_unread_cameras``: the cameras render only for the observations the policy reads: the
    one after a chunk's last action, where the policy's ``needs_next_images()`` asks for it
    (policy.py). For evaluators; observers then see observations without camera images.
    """
    if until not in UNTIL:
        raise ValueError(f"until={until!r}: choose one of {UNTIL}")
    u = env.unwrapped
    obs, info = None, {}
    if reset:
        obs, info = env.reset(seed=seed) if options is None else env.reset(seed=seed, options=options)
        for o in observers:
            o.on_reset(env, obs, info)
    ep = Episode(obs=obs, info=info, privileged=may_plan_on_env(policy))
    if ep.privileged:
        policy.bind(env)
    try:
        policy.reset(getattr(u, "instruction", ""), seed)
    except Exception as e:  # noqa: BLE001 - a failing policy is a result
        ep.termination, ep.error, ep.exception, ep.failed_in = "policy_error", _error_text(e, "policy.reset()"), e, \
            "policy.reset()"
        return ep
    skipping = skip_unread_cameras and hasattr(u, "skip_cameras_next_step")
    while ep.termination is None:
        where = "policy.act()"
        try:
            actions = action_chunk(policy.act(obs), u, replan_steps)
            where = "policy.needs_next_images()"
            read_last = not skipping or bool(getattr(policy, "needs_next_images", lambda: True)())
        except Exception as e:  # noqa: BLE001
            ep.termination, ep.error, ep.exception, ep.failed_in = "policy_error", _error_text(e, where), e, where
            break
        for i, action in enumerate(actions):
            if skipping and (i < len(actions) - 1 or not read_last):
                u.skip_cameras_next_step()
            try:
                result = env.step(action)
            except SimulationInstabilityError as e:
                ep.termination, ep.error, ep.exception, ep.failed_in = "sim_unstable", str(e), e, "env.step()"
                break
            obs, _, terminated, truncated, info = result
            ep.steps += 1
            ep.obs, ep.info, ep.last_step = obs, info, result
            stop = [o.on_step(env, action, obs, info) for o in observers]  # every observer sees every step
            if any(stop):
                ep.termination = "stopped"
                break
            ep.termination = episode_end(until, terminated, truncated, info)
            if ep.termination is not None:
                break
        if ep.termination is None and until != "episode" and getattr(policy, "done", False):
            ep.termination = "plan_end"
    return ep


class EvaluatorTrace(Observer):
    """The evaluator-side stream of an episode, in one format: per state (the reset's, if the
    rollout reset, then one per step) the instructed object's nodes, D_t, centroid and lowest
    point, every object's centroid, the scene's collapsed tets, and R_t (if a DSR wrapper reports
    it); per step the grasp and
    drop flags (False where the env does not report them), both pad forces, the jaw width and the
    TCP pose.
    Evaluator-only: it reads the env, never an observation.

    ``object_name``: the object followed (default: the instructed one, else the scene's first).
    """

    STATE = ("nodes", "deformation", "object_centroid", "object_min_z", "object_centroids", "collapsed_tets",
             "deformation_ratio")
    STEP = ("is_grasped", "dropped", "pad_force", "gripper_width", "tcp", "tcp_quat")

    def __init__(self, object_name: str | None = None):
        self.object_name = object_name
        self.values: dict[str, list] = {k: [] for k in self.STATE + self.STEP}

    def on_reset(self, env, obs, info) -> None:
        self._observe(env, info, step=False)

    def on_step(self, env, action, obs, info) -> None:
        self._observe(env, info, step=True)

    def _observe(self, env, info: dict, step: bool) -> None:
        u = env.unwrapped
        name = self.object_name or getattr(u, "target_instance", None) or u.object_names[0]
        v = self.values
        nodes = u.soft_nodes(name)
        v["nodes"].append(nodes)
        v["deformation"].append(u.deformation(name))
        v["object_centroid"].append(nodes.mean(axis=0))
        v["object_min_z"].append(float(nodes[:, 2].min()))
        v["object_centroids"].append(np.stack([u.soft_nodes(n).mean(0) for n in u.object_names]))
        v["collapsed_tets"].append(u.collapsed_tets())
        if "deformation_ratio" in info:
            v["deformation_ratio"].append(float(info["deformation_ratio"]))
        if step:
            for flag in ("is_grasped", "dropped"):
                v[flag].append(info_bool(info, flag))  # False where the env does not report it
            pads = u.pad_forces()
            v["pad_force"].append([pads["left"], pads["right"]])
            v["gripper_width"].append(u.gripper_width)
            v["tcp"].append(u.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64))
            v["tcp_quat"].append(u.agent.tcp.pose.q[0].cpu().numpy().astype(np.float64))

    def arrays(self) -> dict[str, np.ndarray]:
        """The recorded fields as arrays (fields the env never reported are left out)."""
        return {k: np.asarray(v) for k, v in self.values.items() if len(v)}
