"""Fingerprints of the physics, the tactile images and the evaluator, for checking a code move bit for bit.

A change of where code lives must not change one bit of what it computes. This runs, on this
machine, the cases that touch every layer and prints one SHA-256 per case (and per step):

- ``expert_soft``: the scripted expert on Object-Soft task 3 (FEM cube), rgb+tactile at 64x64:
  ManiSkill's full state vector (robot, actors, FEM nodes, sleep state), every observation
  array (tactile images and markers included), the reward and the evaluator's info, each step;
- ``expert_rigid``: the same on the rigid twin (Object-Rigid task 3);
  both expert cases also hash the simulation states alone (``states``), so that a change of what
  is observed (a tactile model) is told from a change of the physics;
- ``calibration_trial``: one calibration trial (asset 0, closure 0.6) on SoftGraspLift-v1;
- ``record_<policy>``: the evaluator's record of a policy's first ID episode of task 0 (all
  fields but the wall time), e.g. a committed Diffusion Policy.

    .venv/bin/python scripts/fingerprint.py --out before.json              # at the old commit
    .venv/bin/python scripts/fingerprint.py --compare before.json          # at the new one: exit 1 on a difference

Fingerprints hold on one machine and stack only (docs/install.md): compare a commit against
another on the same machine.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np


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
    h = hashlib.sha256()
    _digest(h, x)
    return h.hexdigest()


def expert_episode(env_id: str, task_id: int, seed: int) -> dict:
    import gymnasium as gym

    import mani_skill_softvt  # noqa: F401  (registers the envs)
    from mani_skill_softvt.evaluation.policies import load_policy
    from mani_skill_softvt.rollout import Observer, rollout

    steps, states = [], []

    class StateHash(Observer):
        def on_reset(self, env, obs, info):
            state = env.unwrapped.get_state()
            states.append(sha(state))
            steps.append(sha([state, obs]))

        def on_step(self, env, action, obs, info):
            state = env.unwrapped.get_state()
            states.append(sha(state))
            steps.append(sha([state, obs, action, info]))

    env = gym.make(env_id, obs_mode="rgb+tactile", task_id=task_id,
                   sensor_configs=dict(width=64, height=64))
    try:
        ep = rollout(env, load_policy("expert"), seed=seed, observers=[StateHash()])
    finally:
        env.close()
    # "states": the simulation alone, to tell a change of what is observed from one of the physics.
    return {"steps": len(steps) - 1, "termination": ep.termination, "episode": sha(steps), "per_step": steps,
            "states": sha(states)}


def calibration_trial() -> dict:
    import gymnasium as gym

    import mani_skill_softvt  # noqa: F401
    from mani_skill_softvt.assets.cards import ASSET_IDS
    try:
        from mani_skill_softvt.calibrate import run_trial
    except ImportError:  # before the trial moved there
        from mani_skill_softvt.calibration.sweep import run_trial

    env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=ASSET_IDS[0])
    try:
        rec = run_trial(env, 0.6, 10_000 + 600)
    finally:
        env.close()
    return {"record": rec, "episode": sha(rec)}


def policy_record(policy: str) -> dict:
    from mani_skill_softvt.evaluation.run import RunConfig
    from mani_skill_softvt.evaluation.runner import NOT_REPRODUCED, evaluate

    run = RunConfig.resolve(policy, tasks=(0,), episodes_per_task=1)
    with tempfile.TemporaryDirectory() as tmp:
        (rec,) = evaluate(run, Path(tmp) / "records.jsonl")
    rec = {k: v for k, v in rec.items() if k not in NOT_REPRODUCED}
    return {"steps": rec["steps"], "r_max": rec["r_max"], "episode": sha(rec)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, help="write the fingerprints here (JSON)")
    p.add_argument("--compare", type=Path, help="compare with fingerprints written before; exit 1 on a difference")
    p.add_argument("--policy", default="baselines/policies/vo-c-cpu.pt", help="the policy whose record is fingerprinted")
    p.add_argument("--cases", nargs="+", default=["expert_soft", "expert_rigid", "calibration_trial", "record"])
    args = p.parse_args(argv)
    runs = {"expert_soft": lambda: expert_episode("SoftVTObjectSoft-v1", 3, 50_003_000),
            "expert_rigid": lambda: expert_episode("SoftVTObjectRigid-v1", 3, 50_003_000),
            "calibration_trial": calibration_trial,
            "record": lambda: policy_record(args.policy)}
    prints = {}
    for case in args.cases:
        prints[case] = runs[case]()
        print(f"{case:18s} {prints[case]['episode']}", {k: v for k, v in prints[case].items()
                                                          if k in ("steps", "termination", "r_max")}, flush=True)
    if args.out:
        args.out.write_text(json.dumps(prints, indent=1))
    if args.compare:
        before = json.loads(args.compare.read_text())
        differ = [c for c in prints if c in before and before[c]["episode"] != prints[c]["episode"]]
        for c in differ:
            a, b = before[c].get("per_step", []), prints[c].get("per_step", [])
            first = next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
            print(f"DIFFERS: {c} (first at step {first}; {len(a)} against {len(b)} states)")
            if "states" in before[c] and "states" in prints[c]:
                same = before[c]["states"] == prints[c]["states"]
                print(f"  its simulation states alone: {'identical (what differs is observed)' if same else 'differ'}")
        print("identical, bit for bit" if not differ else f"{len(differ)} case(s) differ")
        return 1 if differ else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
