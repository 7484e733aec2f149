"""Closed-loop evaluation: run episodes, write one audited record per episode, resume.

Every episode ends in a record, whatever the policy does; its ``termination`` says how:

- ``success``: the task's success predicate held (the env ended the episode);
- ``dropped``: the object fell (the env's failure predicate ended the episode);
- ``timeout``: the step limit came first;
- ``sim_unstable``: the FEM blew up (NaN, or nodes faster than 5 m/s). Scored as a task failure
  and a tolerance violation; ``r_max`` is the peak up to the blow-up;
- ``policy_error``: the policy raised, returned malformed actions (not numbers, wrong shape,
  NaN), or its server refused or dropped the connection; ``error`` holds the message;
- ``worker_died``: the process running the episode died (out of memory, a crash in native
  code, a kill); ``error`` says how. Nothing of the episode survives, so ``r_max`` is ``None``.

A tet of a soft object in the scene that collapses or inverts (a fingertip pressing one node, a
crushing grip) does not end the episode: the FEM recovers from it. ``collapsed_steps`` counts the
states with one, and any makes the episode a tolerance violation (:func:`~.metrics.collapsed`).

Records go to a JSONL file, one line per finished episode, written by the main process only.
Each carries the run's configuration (``policy``, ``obs_mode``, ``control_mode``, and for a
trained policy file its ``policy_sha256``, so that a file retrained under the same name is
another run) and
``record_sha256``, a hash of everything but the wall time (:mod:`.records`). A re-run with the same configuration
skips the episodes already there, after verifying every line, so an interrupted evaluation
neither repeats nor loses an episode and an edited or corrupt record is refused with its file
and line. Episodes run in worker processes, or as Ray tasks with ``ray_address`` (one env per
(suite, task) batch either way; see :mod:`mani_skill_softvt.parallel`).
"""

from __future__ import annotations

import json
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from ..fileio import append_jsonl, file_sha256
from ..provenance.numerics import chosen as chosen_numerics
from ..provenance.numerics import numerics_of, resolved
from ..contracts.observations import CAMERAS, info_bool
from ..parallel import WorkerDiedError, run_tasks
from ..provenance import moved_data_path, same_data_path, today_data_path
from ..rollout import Observer, rollout
from ..provenance.stack import software_stack
from ..tasks.suites import get_suite
from ..version import __version__
from .protocols import episode_key, protocol_of, reset_options
from .sidecar import sidecar
from .records import read_records, seal
from .run import RunConfig
from .wrapper import make_env

TERMINATIONS = ("success", "dropped", "timeout", "sim_unstable", "policy_error", "worker_died")


def run_records(path: Path, run: RunConfig) -> dict[tuple, dict]:
    """The verified records of ``run`` in ``path``, by episode key (resume matches on the run's
    fields: another policy, obs mode, control mode or camera size is another run, and so is another
    policy file's content; records from before the hash was kept match on the rest)."""
    fields = run.record_fields()
    return {episode_key(r): r for r in read_records(path) if is_run_record(r, fields, run.policy.sha256)}


def recorded_obs_modes(path: Path, run: RunConfig) -> set[str]:
    """The obs modes in which ``path`` holds records of ``run`` but for its obs mode (same policy,
    policy file, control mode): where a run was made in another mode than today's default, resuming
    it in that mode continues it instead of starting another run beside it."""
    if not Path(path).is_file():
        return set()
    fields = {k: v for k, v in run.record_fields().items() if k in ("policy", "control_mode")}
    return {r["obs_mode"] for r in read_records(path) if is_run_record(r, fields, run.policy.sha256)}


def is_run_record(rec: dict, fields: dict, policy_sha256: str | None) -> bool:
    # A policy file named in its folder's old spelling (records made before the rename) is the same file.
    return all(same_data_path(rec.get(k), v) if k == "policy" else rec.get(k) == v for k, v in fields.items()) and \
        rec.get("policy_sha256", policy_sha256) == policy_sha256


def camera_size_of(env) -> list[int] | None:
    """(height, width) the env's cameras render at, None in obs modes without images."""
    sensors = env.scene.sensors if env.obs_mode_spec.images else {}
    cameras = [sensors[c] for c in CAMERAS if c in sensors]
    return [int(cameras[0].config.height), int(cameras[0].config.width)] if cameras else None


def run_episode(env, policy, episode: dict, replan_steps: int = 8, on_step=None, policy_spec: str | None = None,
                policy_sha256: str | None = None, observers=()) -> dict:
    """One episode of ``policy`` on a DSR-wrapped env (a :func:`~mani_skill_softvt.rollout.rollout`
    that the env ends); the record with its audit receipt.

    Never raises for what the policy does (see the module docstring for the terminations).
    ``on_step(obs, info)``, if given, sees the reset and every step (episode videos use it).
    ``policy_spec`` is how the policy was named to the evaluator (default: its ``name``);
    ``policy_sha256``, the hash of its file if it is one (kept in the record). ``observers``
    (:class:`~mani_skill_softvt.rollout.Observer`) watch the rollout without changing it: the
    cameras still render only where the policy reads them.
    """
    class Callback(Observer):
        def on_reset(self, env, obs, info):
            on_step(obs, info)

        def on_step(self, env, action, obs, info):
            on_step(obs, info)

    options = reset_options(episode["condition"])
    t0 = time.perf_counter()
    # Cameras render only where the policy reads them; a video (on_step) shows every step's.
    ep = rollout(env, policy, int(episode["seed"]), options=options, replan_steps=replan_steps,
                 observers=[*observers, *([Callback()] if on_step is not None else [])], until="episode",
                 skip_unread_cameras=on_step is None)
    return episode_record(env, episode, termination=ep.termination, error=ep.error, steps=ep.steps, info=ep.info,
                          policy_name=getattr(policy, "name", type(policy).__name__), privileged=ep.privileged,
                          policy_spec=policy_spec, policy_sha256=policy_sha256, wall_s=time.perf_counter() - t0)


def episode_record(env, episode: dict, *, termination: str, error: str | None, steps: int, info: dict,
                   policy_name: str, privileged: bool = False, policy_spec: str | None = None,
                   policy_sha256: str | None = None, wall_s: float | None = None) -> dict:
    """The sealed record of an episode that just ended on the DSR-wrapped ``env`` (the scoring
    and the receipt read from the env as it ended): :func:`run_episode`'s, and that of any other
    loop that drives the env itself (LeRobot's, :mod:`~mani_skill_softvt.integrations.lerobot.env`)."""
    u = env.unwrapped
    material = u.object_material(u.target_instance)
    e = material["youngs_modulus"]  # None for a rigid twin
    receipt = {"youngs_modulus": None if e is None else float(e), "mass": float(material["mass"]),
               "light_intensity": u.live_light_intensity(), "calibration_card_sha256": env.calibration_card.sha256,
               "package_version": __version__, "policy": policy_name, "privileged": privileged,
               "stack": software_stack(), "numerics": resolved()}
    success = termination == "success"
    rec = {**{k: episode[k] for k in ("suite", "task_id", "condition", "seed")},
           "policy": policy_spec or receipt["policy"], "obs_mode": u.obs_mode, "control_mode": u.control_mode,
           "tactile_model": get_suite(episode["suite"]).frames_tactile_model(u.obs_mode), "camera_size": camera_size_of(u),
           "termination": termination, "error": error,
           "success": success, "dsr_success": success and info_bool(info, "dsr_success"),
           "dropped": info_bool(info, "dropped"), "steps": steps, "r_max": float(env.r_max),
           "collapsed_steps": int(env.collapsed_steps),
           "tau_o": env.tau_o, "rigid": env.rigid, "deformation_trace": [float(d) for d in env.deformation_trace],
           "wall_s": None if wall_s is None else round(wall_s, 3), "receipt": receipt}
    if len(u.object_names) > 1:  # a Spatial scene: which instance was instructed, and what became of the other
        rec.update(instructed_instance=u.target_instance, other_in_target=info_bool(info, "other_in_target"),
                   instance_displacement={k: round(float(v), 6) for k, v in env.displacements().items()})
    if policy_sha256 is not None:
        rec["policy_sha256"] = policy_sha256
    return seal(rec)


def worker_died_record(episode: dict, reason: str, run: RunConfig, rigid: bool) -> dict:
    """The record of an episode whose process died: a failure, nothing measured (``r_max`` None)."""
    rec = {**{k: episode[k] for k in ("suite", "task_id", "condition", "seed")}, **run.record_fields(),
           "termination": "worker_died", "error": reason, "success": False, "dsr_success": False, "dropped": False,
           "steps": None, "r_max": None, "collapsed_steps": None, "tau_o": None, "rigid": rigid, "deformation_trace": [],
           "wall_s": None, "receipt": {"package_version": __version__, "privileged": False, "stack": software_stack(),
                       "numerics": resolved()}}
    if run.policy.sha256 is not None:  # kept only for policy files, as in run_episode
        rec["policy_sha256"] = run.policy.sha256
    return seal(rec)


def _worker(batch: list[dict], run: RunConfig, queue) -> int:
    policy = run.policy.load()  # a policy file is read once here, and checked against the run's hash
    # Every reset rebuilds the scene (SoftBodyEnv), so an episode is the same whichever ran before
    # it in this env, a blown-up one included: a resumed run and --reproduce match a full run.
    env = make_env(batch[0]["suite"], batch[0]["task_id"], obs_mode=run.obs_mode, control_mode=run.control_mode,
                   camera_size=run.camera_size)
    try:
        for ep in batch:
            queue.put(("start", ep))
            rec = run_episode(env, policy, ep, policy_spec=run.policy.spec, policy_sha256=run.policy.sha256)
            queue.put(("record", rec))
    finally:
        env.close()
    return len(batch)


def evaluate(run: RunConfig, out: Path, episodes: list[dict] | None = None, workers: int = 1, progress=None,
             ray_address: str | None = None, numerics: str | None = None) -> list[dict]:
    """Run the episodes of ``run`` (or ``episodes``, e.g. a reproduction's) not yet in ``out`` and
    return every record of them.

    Only records of the same run (:meth:`RunConfig.record_fields` and the policy file's SHA-256)
    count as done. The records file is read once; new records are appended as they come.
    ``ray_address`` runs the same (suite, task) batches as Ray tasks instead of ``workers``
    local processes ("local", "auto" or "ray://host:port"); the records are the same. ``numerics``:
    the numerics the episodes run under (:mod:`mani_skill_softvt.provenance.numerics`; None: this process's).
    """
    out = Path(out)
    episodes = run.episodes() if episodes is None else episodes
    done = run_records(out, run)
    wanted = numerics or chosen_numerics().name
    known = sidecar(out) if done else None  # read once, not per record
    todo = [ep for ep in episodes if episode_key(ep) not in done]
    made = sorted({numerics_of(r, known) for r in done.values()} - {wanted})
    if made and todo:  # one file, one numerics (a complete file is read as it is, whatever it was made under)
        raise ValueError(f"{out} holds records of this run made under numerics {', '.join(made)}, and this process "
                         f"runs {wanted}: evaluate into another --out, or set SOFTVT_NUMERICS={made[0]} to complete "
                         "them as they were made (docs/install.md, numerics)")
    if progress is not None:
        progress(len(episodes) - len(todo))
    # A dead worker takes its batch's later episodes with it: run the rest again. Every death
    # records the episode it killed, so this ends.
    while todo:
        batches = defaultdict(list)
        for ep in todo:
            batches[(ep["suite"], ep["task_id"])].append(ep)
        items = [(b, run) for b in batches.values()]
        in_flight, deaths = {}, 0
        for kind, value in run_tasks(_worker, items, workers, ray_address, report_deaths=True,
                                             numerics=numerics):
            if kind == "message":
                tag, payload = value
                key = (payload["suite"], payload["task_id"])
                if tag == "start":
                    in_flight[key] = payload
                    continue
                in_flight.pop(key, None)
                rec = payload
            elif kind == "died":
                index, reason = value
                batch = items[index][0]
                ep = in_flight.pop((batch[0]["suite"], batch[0]["task_id"]), None)
                if ep is None:  # died building its env: not an episode's doing, and would recur
                    raise WorkerDiedError(index, f"{reason} before its first episode began")
                rec = worker_died_record(ep, reason, run, get_suite(ep["suite"]).rigid)
                deaths += 1
            else:
                continue
            append_jsonl(out, rec)  # written at once, so a kill loses nothing
            done[episode_key(rec)] = rec
            if progress is not None:
                progress(1)
        todo = [ep for ep in todo if episode_key(ep) not in done] if deaths else []
    return [done[episode_key(ep)] for ep in episodes if episode_key(ep) in done]


RUN_FIELDS = ("policy", "obs_mode", "control_mode", "camera_size", "policy_sha256")  # what names a run
NOT_REPRODUCED = ("wall_s", "record_sha256")  # the wall time differs run to run, and with it the hash
# Fields records have carried since a later version: a stored record without them is not compared on them.
ADDED_FIELDS = ("instructed_instance", "other_in_target", "instance_displacement")
# The stack and numerics a record names are not results: a reproduction on another stack reports them
# as the reason its bits may differ (evaluate --reproduce), not as a difference of the episode.
NOT_COMPARED_IN_RECEIPT = ("stack", "numerics")


def record_differences(stored: dict, new: dict) -> list[str]:
    """The fields in which two records of one episode differ (the receipt's by ``receipt.<name>``),
    but the wall time."""
    out = []
    for k in sorted(set(stored) | set(new)):
        if k in NOT_REPRODUCED or (k in ADDED_FIELDS and k not in stored):
            continue
        a, b = stored.get(k), new.get(k)
        if k == "policy" and same_data_path(a, b):  # one file, named before and after its folder's rename
            continue
        if isinstance(a, dict) and isinstance(b, dict):
            inner = record_differences({f: v for f, v in a.items() if f not in NOT_COMPARED_IN_RECEIPT},
                                       {f: v for f, v in b.items() if f not in NOT_COMPARED_IN_RECEIPT})
            out += [f"{k}.{f}" for f in inner]
        elif a != b:
            out.append(k)
    return out


def relative_difference(a, b) -> float | None:
    """The largest relative difference, against the larger magnitude, between two numbers or two
    equally long lists of numbers (a field that differs only by rounding, on another machine, say):
    between 0 and 2; None for anything else."""
    if isinstance(a, (bool, str, dict)) or isinstance(b, (bool, str, dict)) or a is None or b is None:
        return None
    try:
        x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    except (TypeError, ValueError):
        return None
    if x.shape != y.shape or x.size == 0:
        return None
    # Against the larger magnitude: symmetric, at most 2 (opposite signs), and a count that went from
    # 0 to 7 reads as 1.0, not as an overflow to infinity (a division by the stored 0).
    scale = np.maximum(np.maximum(np.abs(x), np.abs(y)), np.finfo(float).tiny)
    return float(np.max(np.abs(x - y) / scale))


def single_run(records: list[dict], path: Path) -> str | None:
    """Check that ``records`` (of ``path``) are of one run (policy, modes, camera size, policy
    file) and hold each episode once; the run's policy file hash (None for other policies)."""
    # As in run_records, a record from before the policy's hash was kept belongs to the run of its file.
    # A policy path in a renamed folder's old spelling names the file its new spelling does.
    runs = {json.dumps([today_data_path(r.get(k)) if k == "policy" else r.get(k)
                        for k in RUN_FIELDS if k != "policy_sha256"]) for r in records}
    hashes = {r["policy_sha256"] for r in records if r.get("policy_sha256")}
    if len(runs) > 1 or len(hashes) > 1:
        raise ValueError(f"{path} holds records of {max(len(runs), len(hashes))} run configurations (policy, modes, "
                         "camera size, policy file); give a file of one run")
    keys = [episode_key(r) for r in records]
    if len(set(keys)) < len(keys):
        raise ValueError(f"{path}: an episode appears twice; keep one record of each")
    return next(iter(hashes), None)


def reproduce(path: Path, per_task: int | None = 1, workers: int = 1, progress=None,
              tasks: tuple[int, ...] | None = None) -> list[tuple[dict, dict | None, list[str]]]:
    """Run the first ``per_task`` recorded episodes of each task in ``path`` (of ``tasks`` only, where
    given) again (None: all), with
    the configuration and the numerics they were recorded with (a record made before the numerics
    were pinned ran on each library's native dispatch, and is replayed so); (stored record, new
    record, the fields that differ) each.

    Refuses before running anything if the file holds several runs, or if the policy file is not
    the one the records were made with (its ``policy_sha256``)."""
    path = Path(path)
    records = read_records(path)
    if not records:
        raise ValueError(f"{path}: no records to reproduce")
    sha = single_run(records, path)
    first = records[0]
    # A committed policy the records name by its folder's old spelling is read where it lies now
    # (RunConfig.resolve says so on stderr).
    spec = first["policy"]
    here = (moved_data_path(spec) or spec) if sha is not None else spec
    if sha is not None and not Path(here).is_file():
        raise ValueError(f"{path}: its policy file {spec} does not exist here; run from the directory the records "
                         "name it from (the repository root for committed policies)")
    if sha is not None and file_sha256(Path(here)) != sha:
        raise ValueError(f"{path}: {spec} is not the policy file these records were made with (its SHA-256 "
                         f"differs from their policy_sha256 {sha[:12]}...): it was replaced or retrained")
    size = first.get("camera_size")
    run = RunConfig.resolve(spec, first["obs_mode"], first["control_mode"], tuple(size) if size else None,
                            suite=first["suite"], protocol=protocol_of(first["condition"]))
    missing = sorted(set(tasks or ()) - {r["task_id"] for r in records})
    if missing:
        raise ValueError(f"{path}: holds no records of tasks {missing} (it has {sorted({r['task_id'] for r in records})}); "
                         "name only tasks it holds, or none to reproduce every task")
    chosen, count = [], defaultdict(int)
    for r in records:
        key = (r["suite"], r["task_id"])
        if tasks is not None and r["task_id"] not in tasks:
            continue
        if per_task is None or count[key] < per_task:
            count[key] += 1
            chosen.append(r)
    with tempfile.TemporaryDirectory(prefix="reproduce-") as tmp:
        new = evaluate(run, Path(tmp) / "records.jsonl",
                       [{k: r[k] for k in ("suite", "task_id", "condition", "seed")} for r in chosen], workers,
                       progress=progress, numerics=numerics_of(first, sidecar(path)))
    by_key = {episode_key(r): r for r in new}
    return [(r, by_key.get(episode_key(r)),
             record_differences(r, by_key[episode_key(r)]) if episode_key(r) in by_key else ["(not run)"])
            for r in chosen]
