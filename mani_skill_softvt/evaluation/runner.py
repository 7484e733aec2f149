"""Closed-loop evaluation: run episodes, write one audited record per episode, resume.

Records go to a JSONL file, one line per finished episode, written by the main process only;
a re-run skips the episodes already there, so an interrupted evaluation neither repeats nor
loses an episode. Episodes run in worker processes, or as Ray tasks with ``ray_address``
(one env per (suite, task) batch either way; see :mod:`mani_skill_softvt.parallel`).
"""

from __future__ import annotations

import hashlib
import json
import time
from collections import defaultdict
from pathlib import Path

from .. import __version__
from ..fileio import append_jsonl, read_jsonl
from ..parallel import run_tasks
from .protocols import episode_key


def record_hash(record: dict) -> str:
    body = {k: v for k, v in record.items() if k != "record_sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def run_episode(env, policy, episode: dict, replan_steps: int = 8, on_step=None) -> dict:
    """One episode of ``policy`` on a DSR-wrapped env; the record with its audit receipt.

    ``on_step(obs, info)``, if given, sees the reset and every step (episode videos use it).
    """
    u = env.unwrapped
    options = {} if episode["condition"] == "id" else {"ood": episode["condition"]}
    obs, info = env.reset(seed=int(episode["seed"]), options=options)
    if on_step is not None:
        on_step(obs, info)
    from .policies import ScriptedExpertPolicy

    # Only the built-in scripted experts read the simulator; the runner, not the policy, says so.
    privileged = isinstance(policy, ScriptedExpertPolicy)
    if privileged:
        policy.bind(env)
    policy.reset(u.instruction, int(episode["seed"]))
    material = u.object_material(u.target_instance)
    receipt = {"youngs_modulus": float(material["youngs_modulus"]), "mass": float(material["mass"]),
               "light_intensity": u.live_light_intensity(), "calibration_card_sha256": env.calibration_card.sha256,
               "package_version": __version__, "policy": getattr(policy, "name", type(policy).__name__),
               "privileged": privileged}
    steps, done = 0, False
    t0 = time.perf_counter()
    while not done:
        chunk = policy.act(obs)
        for action in chunk[:replan_steps]:
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            if on_step is not None:
                on_step(obs, info)
            if bool(terminated[0]) or bool(truncated[0]):
                done = True
                break
    rec = {**{k: episode[k] for k in ("suite", "task_id", "condition", "seed")},
           "success": bool(info["task_success"]), "dsr_success": bool(info["dsr_success"]),
           "dropped": bool(info["dropped"][0]), "steps": steps, "r_max": float(info["r_max"]),
           "tau_o": env.tau_o, "rigid": env.rigid, "deformation_trace": [float(d) for d in env.deformation_trace],
           "wall_s": round(time.perf_counter() - t0, 3), "receipt": receipt}
    rec["record_sha256"] = record_hash({k: v for k, v in rec.items() if k != "wall_s"})
    return rec


def _worker(batch: list[dict], policy_spec: str, obs_mode: str, control_mode: str, queue) -> int:
    from .policies import load_policy
    from .wrapper import make_env

    policy = load_policy(policy_spec)
    env = make_env(batch[0]["suite"], batch[0]["task_id"], obs_mode=obs_mode, control_mode=control_mode)
    try:
        for ep in batch:
            queue.put(run_episode(env, policy, ep))
    finally:
        env.close()
    return len(batch)


def evaluate(episodes: list[dict], policy_spec: str, out: Path, workers: int = 1, obs_mode: str = "state_dict",
             control_mode: str = "pd_ee_pose", progress=None, ray_address: str | None = None) -> list[dict]:
    """Run the episodes not yet in ``out`` and return every record of the requested episodes.

    ``ray_address`` runs the same (suite, task) batches as Ray tasks instead of ``workers``
    local processes ("local", "auto" or "ray://host:port"); the records are the same.
    """
    out = Path(out)
    done = {episode_key(r) for r in read_jsonl(out)}
    todo = [ep for ep in episodes if episode_key(ep) not in done]
    if progress is not None:
        progress(len(episodes) - len(todo))
    batches = defaultdict(list)
    for ep in todo:
        batches[(ep["suite"], ep["task_id"])].append(ep)
    items = [(b, policy_spec, obs_mode, control_mode) for b in batches.values()]
    for kind, rec in run_tasks(_worker, items, workers, ray_address):
        if kind == "message":  # one finished episode: write it at once so a kill loses nothing
            append_jsonl(out, rec)
            if progress is not None:
                progress(1)
    wanted = {episode_key(ep) for ep in episodes}
    records = {episode_key(r): r for r in read_jsonl(out) if episode_key(r) in wanted}
    return [records[episode_key(ep)] for ep in episodes if episode_key(ep) in records]
