"""Expert demonstrations recorded: one episode per training seed (the scripted expert's
motion-planning solution, recorded in ManiSkill's trajectory format), screened, logged in the task's
QC log, and the accepted ones merged per task; resumable, in parallel processes or on Ray. The
command is ``python -m mani_skill_softvt.demos generate`` (:mod:`mani_skill_softvt.cli.demos`)."""

from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path

import numpy as np
from mani_skill.trajectory.merge_trajectory import merge_trajectories
from tqdm import tqdm

from ..contracts.actions import GRIPPER_ACTION_VERSION, UPGRADE_COMMAND, normalized_gripper
from ..data.demo_set import DemoSet
from ..data.record import SoftVTRecordEpisode, episode_paths, quiet_maniskill_logger
from ..data.seeds import ID_EPISODES_PER_TASK, id_seed, train_seed
from ..data.trajectory import check_h5, episode_json_line, read_episode, screen
from ..evaluation.wrapper import make_env
from ..expert.pick_place import DEFAULT_PLANNER
from ..expert.solution import SOURCE_DESC, solve
from ..fileio import append_jsonl, atomic_write_json, read_json
from ..provenance.numerics import chosen as chosen_numerics
from ..parallel import run_tasks
from ..physics.config import physics_signature, signature_mismatch


def record_demo(env, seed: int, path: Path, planner: str) -> tuple[list[str], dict]:
    """One expert episode recorded by :class:`~mani_skill_softvt.data.record.SoftVTRecordEpisode`
    into ``path`` (+ its .json), kept only if it passes the screening: returns (problems, episode).

    ``env`` is a DSR-wrapped suite env, reused across episodes. The episode is written under a
    temporary name and renamed when screened, so a killed run never leaves a half-written demo.
    """
    tmp_h5, tmp_json = episode_paths(path.with_name(f"{path.stem}.partial.h5"))
    with quiet_maniskill_logger(logging.ERROR):  # "not installed with git": a pip install has no commit to record
        rec = SoftVTRecordEpisode(env, output_dir=str(path.parent), trajectory_name=tmp_h5.stem, save_video=False,
                                  source_type="motionplanning", source_desc=SOURCE_DESC, record_reward=False,
                                  save_on_reset=False)
    try:
        solve(rec, seed=seed, planner=planner)
        rec.flush_trajectory()
    finally:
        rec.close(close_env=False)
    ep = read_episode(tmp_h5)
    problems = screen(ep)
    if problems:
        tmp_h5.unlink()
        tmp_json.unlink()
    else:
        final_h5, final_json = episode_paths(path)
        os.replace(tmp_json, final_json)
        os.replace(tmp_h5, final_h5)  # last: an episode file on disk is a complete, accepted demo
    return problems, ep


def accepted_demos_expected(demo_set: DemoSet, task_id: int, num: int, accepted: int) -> int:
    """The accepted demos a task holds once ``generate(..., accepted=accepted)`` has run: as many as
    asked for, or more where its QC log lists more among its first ``num`` seeds (a set is never
    shrunk, and a fresh checkout records every one its committed log lists again). The progress
    bar's total, so that re-recording a committed set shows its true length and time left."""
    qc = {r["seed"]: r for r in demo_set.verdicts(task_id)}
    listed = sum(bool(qc.get(train_seed(task_id, i), {}).get("accepted")) for i in range(num))
    return max(accepted, listed)


def _generate_task(suite: str, task_id: int, num: int, accepted: int | None, out: Path, planner: str,
                   control_mode: str, screen_only: bool, queue) -> dict:
    """Record one task's demos: the first ``num`` training seeds, or with ``accepted`` training seeds
    in order until that many are accepted (at most ``num`` seeds), keeping every seed generated
    before (a smaller ``accepted`` never shrinks the set, nor its renderings). The progress queue
    gets one per seed, or with ``accepted`` one per accepted demo the task holds (recorded now or before).
    ``screen_only``: record only seeds the QC log does not list (its verdicts stand for the episodes that
    are not on this machine) and merge nothing, see :func:`generate`."""
    demo_set = DemoSet(out, suite)
    with demo_set.task_lock(task_id):  # another run may hold it: its verdicts are read after it
        qc = {r["seed"]: r for r in demo_set.verdicts(task_id)}
        seeds, kept, recorded = [], 0, False
        env = None
        for i in range(num):
            seed = train_seed(task_id, i)
            if accepted is not None and kept >= accepted and seed not in qc:
                break
            seeds.append(seed)
            missing = seed in qc and qc[seed]["accepted"] and not demo_set.episode_file(task_id, seed).exists()
            if seed not in qc or (missing and not screen_only):
                # New, or accepted but its file is not here: the QC logs are committed, the demos are
                # not, so a fresh checkout records the accepted episodes again (its new verdict is appended).
                if env is None:
                    env = make_env(suite, task_id, obs_mode="none", control_mode=control_mode)
                    demo_set.episode_dir(task_id).mkdir(parents=True, exist_ok=True)
                t0 = time.perf_counter()
                problems, ep = record_demo(env, seed, demo_set.episode_file(task_id, seed), planner)
                line = json.loads(episode_json_line(ep, problems))
                line["wall_s"] = round(time.perf_counter() - t0, 2)
                append_jsonl(demo_set.qc_log(task_id), line)
                qc[seed] = line
                recorded = True
            kept += bool(qc[seed]["accepted"])
            if accepted is None or qc[seed]["accepted"]:  # one per accepted demo held (accepted_demos_expected)
                queue.put(1)
        if env is not None:
            env.close()
        if screen_only:
            return _task_report(demo_set, task_id, seeds)
        return _merge_task(suite, task_id, seeds, out, recorded)


def merged_is_current(final_h5: Path, final_json: Path, seeds: list[int], episode_files: list[Path]) -> bool:
    """Whether a task's merged trajectory already packs exactly these episodes: its h5 opens, its
    json lists the same seeds in the same order, and it was written after every episode file
    changed (one recorded again since, or copied in, is newer: the task is merged again)."""
    if not final_json.exists() or check_h5(final_h5, read=False) is not None:
        return False
    try:
        listed = [int(e["episode_seed"]) for e in read_json(final_json)["episodes"]]
    except (ValueError, KeyError, TypeError):
        return False
    merged_at = min(final_h5.stat().st_mtime_ns, final_json.stat().st_mtime_ns)
    changed = (max(s.st_mtime_ns, s.st_ctime_ns) for s in
               (p.stat() for f in episode_files for p in (f, f.with_suffix(".json")) if p.exists()))
    return listed == list(seeds) and all(t <= merged_at for t in changed)


def _merge_task(suite: str, task_id: int, seeds: list[int], out: Path, recorded: bool = True) -> dict:
    """Pack the task's accepted episodes into ``task<k>.h5`` + ``.json`` with ManiSkill's
    ``merge_trajectories`` (written under temporary names, then renamed). A call that recorded
    nothing keeps a merged file that is current (a resumed campaign's rounds over a finished set
    would otherwise rewrite 1,000 episodes ten times, about a minute a round)."""
    demo_set = DemoSet(out, suite)
    qc = {r["seed"]: r for r in demo_set.verdicts(task_id)}
    accepted_seeds = [s for s in seeds if qc.get(s, {}).get("accepted")]
    accepted = [demo_set.episode_file(task_id, s) for s in accepted_seeds]
    final_h5, final_json = episode_paths(demo_set.trajectory(task_id))
    if accepted and (recorded or not merged_is_current(final_h5, final_json, accepted_seeds, accepted)):
        tmp_h5, tmp_json = episode_paths(final_h5.with_name(f"{final_h5.stem}.partial.h5"))
        with quiet_maniskill_logger():  # it logs every file it merges; the command prints its own progress
            merge_trajectories(str(tmp_h5), [str(p) for p in accepted])
        os.replace(tmp_json, final_json)
        os.replace(tmp_h5, final_h5)
    return _task_report(demo_set, task_id, seeds)


def _task_report(demo_set: DemoSet, task_id: int, seeds: list[int]) -> dict:
    """A task's row of ``qc_report.json``, from its QC log's verdicts on ``seeds``."""
    qc = {r["seed"]: r for r in demo_set.verdicts(task_id)}
    rejected = {s: qc[s]["problems"] for s in seeds if s in qc and not qc[s]["accepted"]}
    return {"task_id": task_id, "generated": sum(s in qc for s in seeds),
            "accepted": sum(bool(qc.get(s, {}).get("accepted")) for s in seeds), "rejected": rejected,
            "train_seeds": [seeds[0], seeds[-1]] if seeds else None,
            "seconds_per_demo": float(np.mean(walls)) if (walls := [qc[s]["wall_s"] for s in seeds
                                                                    if "wall_s" in qc.get(s, {})]) else None}


def generate(suite: str, tasks: list[int], num: int, out: Path, workers: int = 1,
             ray_address: str | None = None, planner: str | None = None, control_mode: str = "pd_ee_pose",
             accepted: int | None = None, screen_only: bool = False) -> dict:
    """Record expert demos per task, one work item per task (local processes or Ray tasks): the
    first ``num`` training seeds, or with ``accepted`` training seeds in order until that many
    demos are accepted, drawing at most ``num`` seeds (a task whose expert fails on some seeds
    still ends with ``accepted`` demos: the paper's 100 per task); seeds generated before are
    kept, so the set never shrinks.

    ``planner`` ("mplib" or "cartesian", default :data:`~mani_skill_softvt.expert.pick_place.DEFAULT_PLANNER`)
    joins the expert's waypoints; each episode records the planner that produced it.
    ``control_mode``: the recorded actions, ``pd_ee_pose`` (the paper's, what the baselines train
    on) or ``pd_joint_pos`` (ManiSkill's motion-planning format, which ``replay -c`` converts into
    every other mode).

    ``screen_only``: grow the set's QC logs (which seeds are accepted) without recording again the
    accepted episodes a log lists that are not on this machine, and without merging. Under the
    pinned numerics an episode recorded again is the same bits, so the logs define the set; a
    campaign spread over sessions on machines that keep nothing screens the seeds first and
    records the set once, on the machine that trains on it (a run without ``screen_only``).

    With ``ray_address`` the tasks write their episodes on the Ray worker's node, so on a
    multi-node cluster ``out`` must be on a shared filesystem.
    """
    if accepted is not None and not 1 <= accepted <= num:
        raise ValueError(f"--accepted {accepted}: give 1 to --num ({num}); --num caps the seeds a task draws")
    planner = planner or DEFAULT_PLANNER
    demo_set = DemoSet(out, suite)
    if demo_set.manifest.exists():  # resuming: the new episodes must come from the same physics
        recorded = read_json(demo_set.manifest)
        stale = signature_mismatch(recorded.get("physics"))
        if recorded.get("control_mode", "pd_ee_pose") != control_mode:
            raise ValueError(f"{demo_set.manifest}: the demos there record {recorded.get('control_mode', 'pd_ee_pose')} "
                             f"actions, not {control_mode}; generate into another --out (or convert them with "
                             f"python -m mani_skill_softvt.integrations.maniskill.replay -c {control_mode})")

        if normalized_gripper(control_mode) and recorded.get("gripper_action_version", 1) != GRIPPER_ACTION_VERSION:
            raise ValueError(f"{demo_set.manifest}: the {control_mode} demos there command the gripper by its closure "
                             f"in [0, 1], not by ManiSkill's normalised action; generate into another --out, or convert "
                             f"each task<k>.h5 there with `{UPGRADE_COMMAND} FILE.h5` and set "
                             f"\"gripper_action_version\": {GRIPPER_ACTION_VERSION} in the manifest")
        if stale:
            raise ValueError(f"{demo_set.manifest}: the demos there were recorded under other physics "
                             f"({'; '.join(stale)}); generate into another --out, or move {demo_set.dir} away")
        numerics = recorded.get("numerics")
        if numerics is not None and numerics != chosen_numerics().name:
            raise ValueError(f"{demo_set.manifest}: the demos there were recorded under numerics {numerics}, this "
                             f"process runs {chosen_numerics().name}; generate into another --out, or set "
                             f"SOFTVT_NUMERICS={numerics} to extend them")
        if numerics is None and any(demo_set.dir.glob("task*.h5")):
            print(f"note: {demo_set.manifest} names no numerics (a set from before the pins); the episodes recorded "
                  f"now run under {chosen_numerics().name}")
    # Written first (a resumed run checks its physics), and again with the seeds actually drawn.
    _write_manifest(demo_set, tasks, planner, control_mode, physics_signature(), None if accepted else num)
    total = sum(accepted_demos_expected(demo_set, t, num, accepted) for t in tasks) if accepted else len(tasks) * num
    bar = tqdm(total=total, desc=f"demos {suite}", unit="accepted demo" if accepted else "seed")
    results = []
    out_abs = Path(out).resolve()  # workers (Ray's above all) need not share our working directory
    for kind, value in run_tasks(_generate_task, [(suite, t, num, accepted, out_abs, planner, control_mode, screen_only)
                                                  for t in tasks],
                                 workers, ray_address):
        if kind == "message":
            bar.update(value)
        else:
            results.append(value)
    bar.close()
    _write_manifest(demo_set, tasks, planner, control_mode, physics_signature(), None)
    report = {"suite": suite, "tasks": sorted(results, key=lambda r: r["task_id"])}
    with demo_set.suite_lock():  # the file keeps the rows of tasks another run reported
        rows = {r["task_id"]: r for r in (read_json(demo_set.qc_report).get("tasks", [])
                                          if demo_set.qc_report.exists() else [])}
        rows.update({r["task_id"]: r for r in results})
        atomic_write_json(demo_set.qc_report, {"suite": suite, "tasks": [rows[t] for t in sorted(rows)]})
    return report


def _write_manifest(demo_set: DemoSet, tasks: list[int], planner: str, control_mode: str, physics: dict,
                    num: int | None) -> None:
    """``manifest.json``: per task the training-seed range generated (from its QC log, or the first
    ``num`` if more) and the ID evaluation range, which never overlap. Tasks an earlier manifest
    lists stay listed (a run over some tasks, or another run's, never drops the others)."""
    requested = set(tasks)

    def last_index(t: int) -> int:  # another run's task: only its log counts
        logged = [r["seed"] - train_seed(t, 0) for r in demo_set.verdicts(t)]
        return max(logged + [(num or 0) - 1 if t in requested else 0, 0])

    # Only ManiSkill's modes changed their gripper encoding: pd_ee_pose manifests stay as they were.
    gripper = {"gripper_action_version": GRIPPER_ACTION_VERSION} if normalized_gripper(control_mode) else {}
    # The numerics the episodes were recorded under (numerics.py); a set from before the pins names none.
    numerics = {"numerics": chosen_numerics().name}
    with demo_set.suite_lock():
        if demo_set.manifest.exists():
            old = read_json(demo_set.manifest)
            tasks = sorted(set(tasks) | {int(t) for t in old.get("train_seeds", {})})
            numerics = {"numerics": old["numerics"]} if "numerics" in old else {}
        atomic_write_json(demo_set.manifest, {
            "suite": demo_set.suite, "expert_planner": planner, "control_mode": control_mode, **gripper,
            "physics": physics, **numerics,
            "train_seeds": {t: [train_seed(t, 0), train_seed(t, last_index(t))] for t in tasks},
            "id_eval_seeds": {t: [id_seed(t, 0), id_seed(t, ID_EPISODES_PER_TASK - 1)] for t in tasks},
            "note": "training and evaluation seed ranges are disjoint by construction"})
