"""Fingerprints: one SHA-256 per computation that reaches a record, to check its bits.

Two uses. A code move must not change one bit of what the code computes (``scripts/fingerprint.py
--out before.json`` at the old commit, ``--compare`` at the new one); and under the pinned numerics
(:mod:`mani_skill_softvt.numerics`) the same bits must come out on any x86-64 machine, which the
default tests check against the committed goldens (``tests/golden/fingerprints.json``). The cases:

- ``expert_soft`` / ``expert_rigid``: the scripted expert on Object-Soft / Object-Rigid task 3 in
  rgb+tactile at 64x64: ManiSkill's full state (robot, actors, FEM nodes, sleep state), every
  observation array, reward and info, each step; besides, the states alone (``states``: the
  physics), the camera images alone (``rgb``: the renderer) and the tactile arrays alone
  (``tactile``), so a difference is traced to the part that made it;
- ``tactile_frame``: the GelSight model alone on a fixed sphere pressed, sheared and twisted
  into the gel (pressure and rigid models): image, indentation map and markers;
- ``dp_inference``: a committed Diffusion Policy's action chunk for a fixed observation window
  and noise seed (its bfloat16 encoders and U-Net, DDIM);
- ``dp_training``: a small Diffusion Policy config trained some steps on fixed synthetic windows:
  the weights, EMA and losses;
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


def _synthetic_window(cfg, model, rng: np.random.Generator, batch: int) -> dict:
    """Observation windows of ``batch`` samples with fixed pseudo-random content."""
    import torch

    t = cfg.obs_horizon
    obs = {"state": torch.from_numpy(rng.normal(size=(batch, t, cfg.state_dim)).astype(np.float32))}
    for k in model.image_keys:
        h, w = cfg.tactile_size if k.startswith("tactile") else cfg.camera_size
        c = cfg.tactile_channels if k.startswith("tactile") else 3
        obs[k] = torch.from_numpy(rng.integers(0, 256, (batch, t, h, w, c), dtype=np.uint8))
    if cfg.tactile:
        obs["markers"] = torch.from_numpy(rng.normal(size=(batch, t, 2, cfg.marker_count, 2)).astype(np.float32))
    return obs


def dp_inference(policy: str | Path = "baselines/policies/vt-c-cpu.pt") -> dict:
    """A committed policy's action chunk for a fixed observation window (one thread, as evaluated)."""
    import torch

    from .baselines.agent import load_policy_file
    from .baselines.model import noise_scheduler

    cfg, model, _ = load_policy_file(Path(policy))
    model.eval()
    obs = _synthetic_window(cfg, model, np.random.default_rng(0), 1)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        chunk = model.sample(obs, torch.Generator().manual_seed(0), noise_scheduler(cfg, inference=True))
    finally:
        torch.set_num_threads(threads)
    return {"chunk": chunk.numpy().round(6).tolist()[0][:2], "episode": sha(chunk)}


def dp_training(steps: int = 200, variant: str = "vt-c") -> dict:
    """A small Diffusion Policy (the ``cpu`` preset's architecture, narrower; bfloat16 mixed
    precision) trained ``steps`` steps of batch 8 on fixed synthetic windows, on one thread."""
    import torch

    from .baselines.config import make_config
    from .baselines.dataset import DemoWindows
    from .baselines.model import DiffusionPolicyModel, empty_stats
    from .baselines.train import Training

    cfg = make_config(variant, camera_size=(32, 32), tactile_size=(24, 32), encoder_widths=(8, 16),
                      encoder_blocks=(1, 1), image_feature_dim=16, unet_dims=(16, 32), timestep_embed_dim=16,
                      unet_groups=4, batch_size=8, steps=steps, warmup_steps=10, train_timesteps=50, threads=1)
    rng = np.random.default_rng(0)
    episodes, length = 4, 20
    probe = DiffusionPolicyModel(cfg, empty_stats(cfg))
    frames = {k: v[:, 0].numpy() for k, v in _synthetic_window(cfg, probe, rng, episodes * (length + 1)).items()}
    actions = rng.normal(size=(episodes * length, cfg.action_dim)).astype(np.float32)
    windows = DemoWindows(frames, actions, np.arange(episodes + 1) * (length + 1), np.arange(episodes + 1) * length, cfg)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        run = Training(cfg, windows.stats(), steps)
        for _ in range(steps):
            run.train_step(windows)
    finally:
        torch.set_num_threads(threads)
    weights = {"model": run.model.state_dict(), "ema": run.policy_state()}
    return {"last_loss": round(run.losses[-1], 6), "losses": sha(run.losses), "weights": sha(weights),
            "episode": sha([weights, run.losses])}


def calibration_trial() -> dict:
    """One calibration trial (asset 0, closure 0.6)."""
    import gymnasium as gym

    from .assets.cards import ASSET_IDS
    from .calibrate import run_trial

    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=ASSET_IDS[0])
    try:
        rec = run_trial(env, 0.6, 10_000 + 600)
    finally:
        env.close()
    return {"record": rec, "episode": sha(rec)}


def policy_record(policy: str = "baselines/policies/object_rigid/vt-c-cpu.pt", suite: str = "object_rigid",
                  task_id: int = 0) -> dict:
    """The evaluator's record of ``policy``'s first ID episode of ``task_id`` in ``suite`` (all but its
    wall time, stack and numerics). The default, a rigid-twin episode of the committed VT-C, runs the
    policy's closed loop with cameras and touch in a fraction of a soft episode's time."""
    from .evaluation.run import RunConfig
    from .evaluation.runner import NOT_REPRODUCED, evaluate

    run = RunConfig.resolve(policy, suite=suite, tasks=(task_id,), episodes_per_task=1)
    with tempfile.TemporaryDirectory() as tmp:
        (rec,) = evaluate(run, Path(tmp) / "records.jsonl")
    # The stack, numerics and package version name the run; they are not what it computed.
    receipt = {k: v for k, v in rec["receipt"].items() if k not in ("stack", "numerics", "package_version")}
    rec = {**{k: v for k, v in rec.items() if k not in NOT_REPRODUCED}, "receipt": receipt}
    return {"steps": rec["steps"], "r_max": rec["r_max"], "termination": rec["termination"], "episode": sha(rec)}


CASES = {"expert_soft": lambda: expert_episode("SoftVTObjectSoft-v1"),
         "expert_rigid": lambda: expert_episode("SoftVTObjectRigid-v1"),
         "tactile_frame": tactile_frame, "dp_inference": dp_inference, "dp_training": dp_training,
         "calibration_trial": calibration_trial, "record": policy_record}
