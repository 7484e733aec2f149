"""Closed-loop evaluation: run episodes, write one audited record per episode, resume.

Every episode ends in a record, whatever the policy does; its ``termination`` says how:

- ``success``: the task's success predicate held (the env ended the episode);
- ``dropped``: the object fell (the env's failure predicate ended the episode);
- ``timeout``: the step limit came first;
- ``sim_unstable``: the FEM left its valid range (the object was crushed or torn). Scored as a
  task failure and a tolerance violation; ``r_max`` is the peak up to the blow-up;
- ``policy_error``: the policy raised, returned malformed actions (not numbers, wrong shape,
  NaN), or its server refused or dropped the connection; ``error`` holds the message;
- ``worker_died``: the process running the episode died (out of memory, a crash in native
  code, a kill); ``error`` says how. Nothing of the episode survives, so ``r_max`` is ``None``.

Records go to a JSONL file, one line per finished episode, written by the main process only.
Each carries the run's configuration (``policy``, ``obs_mode``, ``control_mode``) and
``record_sha256``, a hash of everything but the wall time. A re-run with the same configuration
skips the episodes already there, after verifying every line, so an interrupted evaluation
neither repeats nor loses an episode and an edited or corrupt record is refused with its file
and line. Episodes run in worker processes, or as Ray tasks with ``ray_address`` (one env per
(suite, task) batch either way; see :mod:`mani_skill_softvt.parallel`).
"""

from __future__ import annotations

import hashlib
import json
import time
from collections import defaultdict
from pathlib import Path

from .. import __version__
from ..fileio import append_jsonl, read_jsonl_lines
from ..observations import info_bool
from ..parallel import WorkerDiedError, run_tasks
from ..tactile.constants import MODEL_VERSION as TACTILE_MODEL_VERSION
from .protocols import episode_key

TERMINATIONS = ("success", "dropped", "timeout", "sim_unstable", "policy_error", "worker_died")
UNHASHED = ("record_sha256", "wall_s")  # wall time differs run to run; everything else must not


class RecordIntegrityError(ValueError):
    """A stored record that is not what the evaluator wrote (edited, corrupt, or not a record)."""


def record_hash(record: dict) -> str:
    """SHA-256 of the record without its hash and wall time (canonical JSON)."""
    body = {k: v for k, v in record.items() if k not in UNHASHED}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def read_records(path: Path) -> list[dict]:
    """The records of an evaluation log, each verified against its ``record_sha256``.

    A torn last line (a writer killed mid-line) is dropped, as :func:`~mani_skill_softvt.fileio.read_jsonl_lines`
    does; any other bad line raises :class:`RecordIntegrityError` naming the file and line.
    """
    out = []
    for lineno, rec in read_jsonl_lines(path):
        where = f"{path}:{lineno}"
        if not isinstance(rec, dict) or "record_sha256" not in rec:
            raise RecordIntegrityError(f"{where}: not an evaluation record (no record_sha256); "
                                       "remove the line, or evaluate into another --out")
        if rec["record_sha256"] != record_hash(rec):
            raise RecordIntegrityError(f"{where}: the record does not match its record_sha256 (edited or corrupt); "
                                       "remove the line to re-run that episode")
        out.append(rec)
    return out


def run_records(path: Path, policy: str, obs_mode: str, control_mode: str,
                camera_size: tuple[int, int] | None = None) -> dict[tuple, dict]:
    """The verified records of one run configuration in ``path``, by episode key (resume matches on
    the configuration: another policy, obs mode, control mode or camera size is another run)."""
    config = {"policy": policy, "obs_mode": obs_mode, "control_mode": control_mode,
              "tactile_model": tactile_model(obs_mode), "camera_size": recorded_camera_size(obs_mode, camera_size)}
    return {episode_key(r): r for r in read_records(path) if all(record_field(r, k) == v for k, v in config.items())}


def tactile_model(obs_mode: str) -> int | None:
    """The tactile model version of this package's frames in ``obs_mode`` (None without touch)."""
    return TACTILE_MODEL_VERSION if "tactile" in obs_mode else None


def recorded_camera_size(obs_mode: str, camera_size: tuple[int, int] | None) -> list[int] | None:
    """The ``camera_size`` a record of a run in ``obs_mode`` carries: the cameras' (height, width),
    the native 224x224 unless asked otherwise; None in obs modes without images."""
    from ..observations import NATIVE_CAMERA_SIZE

    return [int(v) for v in (camera_size or NATIVE_CAMERA_SIZE)] if str(obs_mode).startswith("rgb") else None


def record_field(rec: dict, key: str):
    """A record's field; records from before the tactile model was kept have model 1, those from
    before the camera size was kept had 224x224 cameras."""
    if key == "tactile_model" and key not in rec:
        return 1 if "tactile" in str(rec.get("obs_mode")) else None
    if key == "camera_size" and key not in rec:
        return recorded_camera_size(rec.get("obs_mode"), None)
    return rec.get(key)


def camera_size_of(env) -> list[int] | None:
    """(height, width) the env's cameras render at, None in obs modes without images."""
    from ..observations import CAMERAS

    sensors = env.scene.sensors if "rgb" in env.obs_mode else {}
    cameras = [sensors[c] for c in CAMERAS if c in sensors]
    return [int(cameras[0].config.height), int(cameras[0].config.width)] if cameras else None


def _seal(rec: dict) -> dict:
    rec["record_sha256"] = record_hash(rec)
    return rec


def run_episode(env, policy, episode: dict, replan_steps: int = 8, on_step=None, policy_spec: str | None = None) -> dict:
    """One episode of ``policy`` on a DSR-wrapped env (a :func:`~mani_skill_softvt.rollout.rollout`
    that the env ends); the record with its audit receipt.

    Never raises for what the policy does (see the module docstring for the terminations).
    ``on_step(obs, info)``, if given, sees the reset and every step (episode videos use it).
    ``policy_spec`` is how the policy was named to the evaluator (default: its ``name``).
    """
    from ..rollout import Observer, rollout

    class Callback(Observer):
        def on_reset(self, env, obs, info):
            on_step(obs, info)

        def on_step(self, env, action, obs, info):
            on_step(obs, info)

    u = env.unwrapped
    options = {} if episode["condition"] == "id" else {"ood": episode["condition"]}
    t0 = time.perf_counter()
    ep = rollout(env, policy, int(episode["seed"]), options=options, replan_steps=replan_steps,
                 observers=[Callback()] if on_step is not None else [], until="episode")
    info = ep.info
    material = u.object_material(u.target_instance)
    e = material["youngs_modulus"]  # None for a rigid twin
    receipt = {"youngs_modulus": None if e is None else float(e), "mass": float(material["mass"]),
               "light_intensity": u.live_light_intensity(), "calibration_card_sha256": env.calibration_card.sha256,
               "package_version": __version__, "policy": getattr(policy, "name", type(policy).__name__),
               "privileged": ep.privileged}
    success = ep.termination == "success"
    rec = {**{k: episode[k] for k in ("suite", "task_id", "condition", "seed")},
           "policy": policy_spec or receipt["policy"], "obs_mode": u.obs_mode, "control_mode": u.control_mode,
           "tactile_model": tactile_model(u.obs_mode), "camera_size": camera_size_of(u),
           "termination": ep.termination, "error": ep.error,
           "success": success, "dsr_success": success and info_bool(info, "dsr_success"),
           "dropped": info_bool(info, "dropped"), "steps": ep.steps, "r_max": float(env.r_max),
           "tau_o": env.tau_o, "rigid": env.rigid, "deformation_trace": [float(d) for d in env.deformation_trace],
           "wall_s": round(time.perf_counter() - t0, 3), "receipt": receipt}
    return _seal(rec)


def worker_died_record(episode: dict, reason: str, config: dict, rigid: bool) -> dict:
    """The record of an episode whose process died: a failure, nothing measured (``r_max`` None)."""
    rec = {**{k: episode[k] for k in ("suite", "task_id", "condition", "seed")}, **config,
           "camera_size": recorded_camera_size(config["obs_mode"], config.get("camera_size")),
           "tactile_model": tactile_model(config["obs_mode"]), "termination": "worker_died", "error": reason, "success": False, "dsr_success": False, "dropped": False,
           "steps": None, "r_max": None, "tau_o": None, "rigid": rigid, "deformation_trace": [], "wall_s": None,
           "receipt": {"package_version": __version__, "privileged": False}}
    return _seal(rec)


def _worker(batch: list[dict], policy_spec: str, obs_mode: str, control_mode: str, camera_size, queue) -> int:
    from .policies import load_policy
    from .wrapper import make_env

    policy = load_policy(policy_spec)

    def build():
        return make_env(batch[0]["suite"], batch[0]["task_id"], obs_mode=obs_mode, control_mode=control_mode,
                        camera_size=camera_size)

    env = build()
    try:
        for ep in batch:
            queue.put(("start", ep))
            rec = run_episode(env, policy, ep, policy_spec=policy_spec)
            queue.put(("record", rec))
            if rec["termination"] == "sim_unstable":  # start the next episode from a freshly built simulator
                env.close()
                env = build()
    finally:
        env.close()
    return len(batch)


def evaluate(episodes: list[dict], policy_spec: str, out: Path, workers: int = 1, obs_mode: str = "state_dict",
             control_mode: str = "pd_ee_pose", progress=None, ray_address: str | None = None,
             camera_size: tuple[int, int] | None = None) -> list[dict]:
    """Run the episodes not yet in ``out`` and return every record of the requested episodes.

    The cameras render at ``camera_size`` (height, width), by default the size the policy asks for
    (:func:`~mani_skill_softvt.evaluation.policies.policy_camera_size`; 224x224 if none); asking a
    policy that says another size is an error. Only records of the same configuration (policy,
    obs mode, control mode, camera size) count as done.
    ``ray_address`` runs the same (suite, task) batches as Ray tasks instead of ``workers``
    local processes ("local", "auto" or "ray://host:port"); the records are the same.
    """
    from ..observations import camera_sensor_configs
    from ..tasks.suites import get_suite
    from .policies import policy_camera_size

    out = Path(out)
    wanted = policy_camera_size(policy_spec)
    if camera_size is not None and wanted is not None and tuple(camera_size) != tuple(wanted):
        raise ValueError(f"policy {policy_spec} was trained on {wanted[0]}x{wanted[1]} cameras; evaluate it at that "
                         f"size (leave camera_size out), not {camera_size[0]}x{camera_size[1]}")
    camera_size = tuple(camera_size or wanted or ()) or None
    camera_sensor_configs(camera_size)  # a size too small is an error here, naming it, not in a worker
    config = {"policy": policy_spec, "obs_mode": obs_mode, "control_mode": control_mode, "camera_size": camera_size}
    done = run_records(out, **config)
    todo = [ep for ep in episodes if episode_key(ep) not in done]
    if progress is not None:
        progress(len(episodes) - len(todo))
    # A dead worker takes its batch's later episodes with it: run the rest again. Every death
    # records the episode it killed, so this ends.
    ran = bool(todo)
    while todo:
        batches = defaultdict(list)
        for ep in todo:
            batches[(ep["suite"], ep["task_id"])].append(ep)
        items = [(b, policy_spec, obs_mode, control_mode, camera_size) for b in batches.values()]
        in_flight, deaths = {}, 0
        for kind, value in run_tasks(_worker, items, workers, ray_address, report_deaths=True):
            if kind == "message":
                tag, payload = value
                key = (payload["suite"], payload["task_id"])
                if tag == "start":
                    in_flight[key] = payload
                    continue
                in_flight.pop(key, None)
                append_jsonl(out, payload)  # written at once, so a kill loses nothing
            elif kind == "died":
                index, reason = value
                batch = items[index][0]
                ep = in_flight.pop((batch[0]["suite"], batch[0]["task_id"]), None)
                if ep is None:  # died building its env: not an episode's doing, and would recur
                    raise WorkerDiedError(index, f"{reason} before its first episode began")
                append_jsonl(out, worker_died_record(ep, reason, config, get_suite(ep["suite"]).rigid))
                deaths += 1
            else:
                continue
            if progress is not None:
                progress(1)
        done = run_records(out, **config)
        todo = [ep for ep in todo if episode_key(ep) not in done] if deaths else []
    records = run_records(out, **config) if ran else done
    return [records[episode_key(ep)] for ep in episodes if episode_key(ep) in records]
