"""Fingerprints: one SHA-256 per computation that reaches a record, to check its bits.

Two uses. A code move must not change one bit of what the code computes (``scripts/fingerprint.py
--out before.json`` at the old commit, ``--compare`` at the new one); and under the pinned numerics
(:mod:`mani_skill_softvt.provenance.numerics`) the same bits must come out on any x86-64 machine, which the
default tests check against the committed goldens (``tests/golden/fingerprints.json``). The cases:

- ``expert_soft`` / ``expert_rigid``: the scripted expert on Object-Soft / Object-Rigid task 3 in
  rgb+tactile at 64x64: ManiSkill's full state (robot, actors, FEM nodes, sleep state), every
  observation array, reward and info, each step; besides, the states alone (``states``: the
  physics), the camera images alone (``rgb``: the renderer) and the tactile arrays alone
  (``tactile``), so a difference is traced to the part that made it;
- ``tactile_frame``: the GelSight model alone on a fixed sphere pressed, sheared and twisted
  into the gel (pressure and rigid models): image, indentation map and markers;
- ``dp_inference`` and ``dp_training``: the Diffusion Policy baselines' cases, in the campaign's
  distribution (:mod:`softvt_campaign.fingerprints`, which the library does not import);
- ``calibration_trial``: one calibration trial (asset 0, closure 0.6) on SoftGraspLift-v1;
- ``record``: the evaluator's record of a committed policy's first ID episode of task 0 (all
  fields but the wall time, the stack, the numerics and the package version).
"""

from __future__ import annotations

import hashlib
import tempfile
from pathlib import Path

import numpy as np


GOLDEN_SEED = 50_003_000  # an ID seed of task 3


def _digest(h, x) -> None:
    """Feed arrays, tensors, numbers and nested dicts/lists into ``h`` in a fixed order."""
    if isinstance(x, dict):
        for k in sorted(x):
            h.update(str(k).encode())
            _digest(h, x[k])
    elif isinstance(x, (list, tuple)):
        for v in x:
            _digest(h, v)
    elif hasattr(x, "detach"):
        _digest(h, x.detach().cpu().numpy())
    elif isinstance(x, np.ndarray):
        h.update(str(x.dtype).encode() + str(x.shape).encode())
        h.update(np.ascontiguousarray(x).tobytes())
    else:
        h.update(repr(x).encode())


def sha(x) -> str:
    """SHA-256 of nested arrays, tensors, numbers, dicts and lists (dict keys sorted)."""
    h = hashlib.sha256()
    _digest(h, x)
    return h.hexdigest()


def _split(obs: dict) -> tuple[dict, dict]:
    """(camera images, tactile arrays) of an rgb+tactile observation."""
    return obs.get("sensor_data", {}), obs.get("tactile", {})


def expert_episode(env_id: str, task_id: int = 3, seed: int = GOLDEN_SEED, max_steps: int | None = None) -> dict:
    """The scripted expert's episode (``max_steps``: stop after that many steps)."""
    import gymnasium as gym

    from .evaluation.policies import load_policy
    from .rollout import Observer, rollout

    steps, states, rgb, tactile = [], [], [], []

    class Hashes(Observer):
        def _see(self, env, obs, extra):
            state = env.unwrapped.get_state()
            images, touch = _split(obs)
            states.append(sha(state))
            rgb.append(sha(images))
            tactile.append(sha(touch))
            steps.append(sha([state, obs, *extra]))

        def on_reset(self, env, obs, info):
            self._see(env, obs, [])

        def on_step(self, env, action, obs, info):
            self._see(env, obs, [action, info])

    env = gym.make(env_id, obs_mode="rgb+tactile", task_id=task_id, sensor_configs=dict(width=64, height=64))
    if max_steps is not None:
        env = gym.wrappers.TimeLimit(env, max_steps)
    try:
        ep = rollout(env, load_policy("expert"), seed=seed, observers=[Hashes()])
    finally:
        env.close()
    return {"steps": len(steps) - 1, "termination": ep.termination, "episode": sha(steps), "per_step": steps,
            "states": sha(states), "rgb": sha(rgb), "tactile": sha(tactile)}


def tactile_frame() -> dict:
    """The GelSight model on a fixed sphere (radius 12 mm) pressed 0.4 mm into the gel, then
    sheared 0.3 mm and twisted 3 degrees: the pressure (soft) and force-balance (rigid) models."""
    import trimesh

    from .tactile import TactileSensor

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.012)
    v0, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    out = {}
    for model, kwargs in {"pressure": dict(normal_force=2.0, deformable=True),
                          "rigid": dict(normal_force=2.0, deformable=False),
                          "geometric": dict(normal_force=None)}.items():
        sensor = TactileSensor("left")
        frames = []
        for shear, twist in ((0.0, 0.0), (0.3e-3, np.deg2rad(3.0))):
            c, s = np.cos(twist), np.sin(twist)
            v = v0 @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [shear, 0.0, 0.012 - 0.4e-3]
            fr = sensor.render_local(v, f, **kwargs)
            frames.append([fr.image, fr.depth, fr.marker_current])
        out[model] = sha(frames)
    return {**out, "episode": sha(out)}


def calibration_trial() -> dict:
    """One calibration trial (asset 0, closure 0.6)."""
    import gymnasium as gym

    from .assets.cards import ASSET_IDS
    from .expert.calibration_trials import run_trial

    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=ASSET_IDS[0])
    try:
        rec = run_trial(env, 0.6, 10_000 + 600)
    finally:
        env.close()
    return {"record": rec, "episode": sha(rec)}


def policy_record(policy: str = "campaign-data/policies/object_rigid/vt-c-cpu.pt", suite: str = "object_rigid",
                  task_id: int = 0) -> dict:
    """The evaluator's record of ``policy``'s first ID episode of ``task_id`` in ``suite`` (all but its
    wall time, stack, numerics and the policy's path: its file is named by ``policy_sha256``). The
    default, a rigid-twin episode of the committed VT-C, runs the policy's closed loop with cameras and
    touch in a fraction of a soft episode's time."""
    from .evaluation.run import RunConfig
    from .evaluation.runner import NOT_REPRODUCED, evaluate

    run = RunConfig.resolve(policy, suite=suite, tasks=(task_id,), episodes_per_task=1)
    with tempfile.TemporaryDirectory() as tmp:
        (rec,) = evaluate(run, Path(tmp) / "records.jsonl")
    # The stack, numerics and package version name the run, and the path where the policy file lies
    # (it moved from baselines/policies/) names no computation; they are not what it computed.
    receipt = {k: v for k, v in rec["receipt"].items() if k not in ("stack", "numerics", "package_version")}
    rec = {**{k: v for k, v in rec.items() if k not in (*NOT_REPRODUCED, "policy")}, "receipt": receipt}
    return {"steps": rec["steps"], "r_max": rec["r_max"], "termination": rec["termination"], "episode": sha(rec)}


CASES = {"expert_soft": lambda: expert_episode("SoftVTObjectSoft-v1"),
         "expert_rigid": lambda: expert_episode("SoftVTObjectRigid-v1"),
         "tactile_frame": tactile_frame, "calibration_trial": calibration_trial, "record": policy_record}
