"""DSRWrapper: adds the deformation-aware scoring to every step's info (never to obs), and
:func:`make_env`, the one way the runner, the videos and the demos make a suite env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from .. import tasks  # noqa: F401  (registers the envs)
from ..contracts.observations import camera_sensor_configs, info_bool
from ..tasks.suites import get_suite
from .metrics import deformation_ratio, dsr_success


class DSRWrapper(gym.Wrapper):
    """Wraps a SoftVT suite env. Per step ``info`` gains:

    - ``deformation_ratio``: R_t = D_t / tau_o of the instructed object,
    - ``r_max``: max R_t so far this episode,
    - ``task_success``: the env's kinematic success,
    - ``collapsed_tets``: tets of the scene's soft objects now collapsed or inverted, and
      ``collapsed_steps``: the states with any so far this episode,
    - ``dsr_success``: task success with R_max <= 1 and no collapse so far, on every suite. Rigid
      twins are PhysX rigid bodies, so their R_max is ~0 and DSR equals TSR there by physics (the
      paper's premise), not by a special case.

    tau_o comes from the env's calibration card (``env.unwrapped.calibration_card``: the task's
    soft asset's, rigid twins their soft asset's, loaded once per env), the card the expert draws
    its closures from and the dense reward reads.
    """

    def __init__(self, env: gym.Env):
        super().__init__(env)
        task = env.unwrapped.task
        self.calibration_card = env.unwrapped.calibration_card
        self.tau_o = self.calibration_card.tau_o
        self.rigid = task.rigid  # recorded with each episode
        self.r_max = 0.0
        self.deformation_trace: list[float] = []
        self.collapsed_steps = 0
        self.start_centroids: dict = {}  # each instance's centroid as the episode began

    def displacements(self) -> dict[str, float]:
        """How far (m) each instance's centroid is from where the episode began, in a Spatial scene
        (whether the other instance was disturbed too; empty in an Object scene). Evaluator-only."""
        u = self.env.unwrapped
        return {n: float(np.linalg.norm(u.soft_nodes(n).mean(0) - c)) for n, c in self.start_centroids.items()}

    def _score(self, info: dict) -> dict:
        u = self.env.unwrapped
        d = u.deformation(u.target_instance)
        r = deformation_ratio(d, self.tau_o)
        self.r_max = max(self.r_max, r)
        self.deformation_trace.append(d)
        collapsed = u.collapsed_tets()
        self.collapsed_steps += collapsed > 0
        success = info_bool(info, "success")
        info = dict(info)
        info.update(deformation_ratio=r, r_max=self.r_max, task_success=success, collapsed_tets=collapsed,
                    collapsed_steps=self.collapsed_steps,
                    dsr_success=dsr_success(success, self.r_max, self.collapsed_steps > 0))
        return info

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.r_max, self.deformation_trace, self.collapsed_steps = 0.0, [], 0
        u = self.env.unwrapped
        names = getattr(u, "object_names", ())  # two in a Spatial scene: the other instance is watched too
        self.start_centroids = {n: u.soft_nodes(n).mean(0) for n in names} if len(names) > 1 else {}
        return obs, self._score(info)

    def step(self, action):
        obs, rew, terminated, truncated, info = self.env.step(action)
        return obs, rew, terminated, truncated, self._score(info)


def make_env(suite: str, task_id: int, *, dsr: bool = True, calibration_dir=None,
             camera_size: tuple[int, int] | None = None, **kwargs) -> gym.Env:
    """The env of ``suite``'s task ``task_id`` (``kwargs`` go to ``gym.make``: obs_mode,
    control_mode, max_episode_steps, ...), DSR-wrapped unless ``dsr=False``; its calibration card
    is read from ``calibration_dir`` (default: the package's cards). ``camera_size`` = (height,
    width) renders the two policy cameras at that size (:func:`~mani_skill_softvt.contracts.observations.camera_sensor_configs`)."""
    if calibration_dir is not None:  # only then: recorded env kwargs stay free of machine paths
        kwargs["calibration_dir"] = str(calibration_dir)
    sized = camera_sensor_configs(camera_size)
    if sized:  # only then, likewise: a native env's recorded kwargs stay as they were
        kwargs["sensor_configs"] = {**kwargs.get("sensor_configs", {}), **sized}
    env = gym.make(get_suite(suite).env_id, task_id=task_id, **kwargs)
    return DSRWrapper(env) if dsr else env
