"""Expert demonstrations: generate (resumable, parallel), merge into ManiSkill trajectories, stats.

    python -m mani_skill_softvt.demos generate --suite object_soft --tasks 3 --num 2
    python -m mani_skill_softvt.demos generate --suite spatial_soft --num 100 --workers 2
    python -m mani_skill_softvt.demos generate --suite object_soft --accepted 100 --num 200   # 100 accepted a task
    python -m mani_skill_softvt.demos generate --suite spatial_soft --num 100 --ray auto   # on a Ray cluster
    python -m mani_skill_softvt.demos render --suite object_soft --tasks 3 --obs-mode rgb+tactile
    python -m mani_skill_softvt.demos render --suite object_soft --camera-size 84x84   # at a CPU policy's size
    python -m mani_skill_softvt.demos stats --suite object_soft

``generate`` runs the scripted expert once per episode (training seeds, disjoint from the ID
evaluation seeds; both ranges go to ``manifest.json``), screens every episode (stream lengths,
NaN, success, no drop, R_max <= 1, no collapsed tet), keeps a QC log of what was rejected and why, and packs the
accepted episodes per task into ``<suite>/task<k>.h5`` + ``.json`` (ManiSkill's trajectory format,
``source_type="motionplanning"``). Re-running skips episodes already recorded. Where each file
lives: :class:`~mani_skill_softvt.data.demo_set.DemoSet`.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import shutil
import time
from collections import Counter
from pathlib import Path

import h5py
import numpy as np
from mani_skill.trajectory.merge_trajectory import merge_trajectories
from matplotlib.figure import Figure
from tqdm import tqdm

from .data.demo_set import DemoSet, latest_verdicts
from .integrations.lerobot.export import export_lerobot
from .data.record import SoftVTRecordEpisode, episode_paths, quiet_maniskill_logger
from .data.seeds import ID_EPISODES_PER_TASK, id_seed, train_seed
from .data.trajectory import (
    CorruptDataError,
    check_h5,
    episode_digest,
    episode_json_line,
    holds_twin_contact,
    open_h5,
    read_episode,
    rendering_current,
    rendering_parts_dir,
    screen,
    state_dict_at,
    write_rendering,
)
from .evaluation.wrapper import make_env
from .expert.pick_place import DEFAULT_PLANNER
from .expert.solution import SOURCE_DESC, solve
from .fileio import append_jsonl, atomic_write, atomic_write_json, read_json
from .observations import ObsMode, camera_sensor_configs, camera_size_name, flatten_batch, parse_image_size, tactile_keys
from .parallel import run_tasks
from .paths import DEMOS_DIR, writable_default
from .numerics import chosen as chosen_numerics
from .physics.constants import physics_signature, signature_mismatch
from .tasks.objects import TWIN_CONTACT_STATE
from .actions import GRIPPER_ACTION_VERSION, UPGRADE_COMMAND, normalized_gripper
from .tasks.suites import NUM_TASKS, SUITES, get_suite


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
            "seconds_per_demo": float(np.mean([qc[s]["wall_s"] for s in seeds if s in qc])) if qc else None}


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
                             f"python -m mani_skill_softvt.replay -c {control_mode})")

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


def rerecord_agreement(qc_lines: list[dict]) -> dict:
    """How the episodes a QC log holds twice agree with their first verdict. A fresh checkout
    records again the accepted seeds its committed log lists (another machine, as a rule), and
    appends the new verdict: on another machine the same episode keeps its outcome but not its
    bits. Counts the repeats, those with the first verdict and step count, those whose R_max is the
    same bit for bit, those that diverged (NaN R_max) in one run only, and the largest finite R_max
    difference with its seed (None if every one is the same). Two NaNs (diverged twice) are the same;
    one NaN is counted on its own, since no difference measures it (and JSON has no infinity)."""
    first, agree = {}, {"repeats": 0, "same_verdict": 0, "same_steps": 0, "r_max_equal": 0, "r_max_nan_once": 0,
                        "r_max_largest_difference": 0.0, "r_max_largest_difference_seed": None}
    for line in qc_lines:
        then = first.setdefault(line["seed"], line)
        if then is line:
            continue
        agree["repeats"] += 1
        agree["same_verdict"] += line["accepted"] == then["accepted"]
        agree["same_steps"] += line["steps"] == then["steps"]
        if line.get("r_max") is None or then.get("r_max") is None:
            continue
        diverged = math.isnan(line["r_max"]), math.isnan(then["r_max"])
        if any(diverged):
            agree["r_max_equal" if all(diverged) else "r_max_nan_once"] += 1
            continue
        difference = abs(line["r_max"] - then["r_max"])
        agree["r_max_equal"] += difference == 0.0
        if difference > agree["r_max_largest_difference"]:
            agree["r_max_largest_difference"], agree["r_max_largest_difference_seed"] = difference, line["seed"]
    return agree


def _pooled_agreement(rows: list[dict]) -> dict:
    """:func:`rerecord_agreement` over every task: the counts summed, the largest difference kept."""
    pooled = {k: sum(r["rerecorded"].get(k, 0) for r in rows)
              for k in ("repeats", "same_verdict", "same_steps", "r_max_equal", "r_max_nan_once")}
    worst = max(rows, key=lambda r: r["rerecorded"]["r_max_largest_difference"])["rerecorded"]
    return {**pooled, "r_max_largest_difference": worst["r_max_largest_difference"],
            "r_max_largest_difference_seed": worst["r_max_largest_difference_seed"]}


def stats(suite: str, out: Path) -> dict:
    """Per task: expert success (accepted / generated), R_max median and 95th percentile, episode
    lengths, wall seconds per demo, rejection reasons, and how episodes recorded again agree with
    their first verdict (:func:`rerecord_agreement`). Writes ``stats.json`` and ``r_max_hist.png``
    next to the suite's demos; raises FileNotFoundError when there are none."""
    demo_set = DemoSet(out, suite)
    rows, all_r, corrupt = [], [], []
    for t in range(NUM_TASKS):
        log = demo_set.read_qc(t)
        qc = latest_verdicts(log)
        if not qc:
            continue
        # From the QC log, so an interrupted run (episodes recorded, not yet merged) counts too.
        eps = [q for q in qc if q["accepted"]]
        r = [e["r_max"] for e in eps]
        all_r += r
        walls = [q["wall_s"] for q in qc if "wall_s" in q]
        corrupt += _unreadable_files(demo_set, t, eps)
        rows.append({"task_id": t, "generated": len(qc), "accepted": len(eps), "success_rate": len(eps) / len(qc),
                     **_r_max_summary(r),
                     "length_mean": float(np.mean([e["steps"] for e in eps])) if eps else None,
                     "recorded_here": sum(demo_set.episode_file(t, e["seed"]).exists() for e in eps),
                     "seconds_per_demo": float(np.mean(walls)) if walls else None,
                     "rejected": dict(Counter(p for q in qc for p in q.get("problems", []))),
                     "rerecorded": rerecord_agreement(log)})
    if not rows:
        raise FileNotFoundError(f"no demos of suite '{suite}' under {out}; run "
                                f"'python -m mani_skill_softvt.demos generate --suite {suite} --out {out}' first")
    summary = {"suite": suite, "tasks": rows,
               "generated": sum(r["generated"] for r in rows), "accepted": sum(r["accepted"] for r in rows),
               **_r_max_summary(all_r), "rerecorded": _pooled_agreement(rows), "unreadable_files": corrupt}
    atomic_write_json(demo_set.stats, summary)
    if all_r:
        fig = Figure(figsize=(5, 3))
        ax = fig.subplots()
        ax.hist(all_r, bins=20, range=(0, 1.2), color="tab:blue")
        ax.axvline(1.0, color="k", ls="--")
        ax.set_xlabel("R_max per demo")
        ax.set_ylabel("demos")
        ax.set_title(f"{suite}: {len(all_r)} accepted demos")
        fig.tight_layout()
        atomic_write(demo_set.r_max_histogram, lambda p: fig.savefig(p, dpi=120))
    return summary


def _unreadable_files(demo_set: DemoSet, task_id: int, accepted: list[dict]) -> list[str]:
    """Why each of the task's demo files that should be readable is not: the accepted episodes and
    the merged trajectory are read in full (states only, small); renderings (images, large) are
    opened, which is where a truncated HDF5 file fails."""
    # An accepted episode that is not here is not unreadable: a set screened elsewhere
    # (generate --screen-only) lists it; `recorded_here` in the stats counts those that are.
    files = [p for p in (demo_set.episode_file(task_id, q["seed"]) for q in accepted) if p.exists()]
    files += [p for p in (demo_set.trajectory(task_id),) if p.exists()]
    problems = [check_h5(p) for p in files] + [check_h5(p, read=False) for p in demo_set.renderings(task_id)]
    return [p for p in problems if p]


def _r_max_summary(r_max: list[float]) -> dict:
    """Median, 95th percentile (None without demos) and count above 1 of per-demo R_max values."""
    return {"r_max_median": float(np.median(r_max)) if r_max else None,
            "r_max_p95": float(np.percentile(r_max, 95)) if r_max else None,
            "r_max_above_1": int(sum(x > 1 for x in r_max))}


def format_stats(summary: dict) -> str:
    """The stats of :func:`stats` as a plain-text table, one row per task and a total."""
    def num(x, fmt):
        return "-" if x is None else format(x, fmt)

    head = f"{'task':>4}  {'success':>9}  {'R_max med':>9}  {'R_max p95':>9}  {'>1':>3}  {'steps':>6}  {'s/demo':>6}  rejected"
    lines = [f"{summary['suite']}: expert demos", head, "-" * len(head)]
    for r in summary["tasks"]:
        rej = ", ".join(f"{k} x{v}" for k, v in r["rejected"].items())
        lines.append(f"{r['task_id']:>4}  {r['accepted']:>4}/{r['generated']:<4}  {num(r['r_max_median'], '9.3f')}  "
                     f"{num(r['r_max_p95'], '9.3f')}  {r['r_max_above_1']:>3}  {num(r['length_mean'], '6.1f')}  "
                     f"{num(r['seconds_per_demo'], '6.1f')}  {rej}")
    lines.append("-" * len(head))
    lines.append(f"{'all':>4}  {summary['accepted']:>4}/{summary['generated']:<4}  {num(summary['r_max_median'], '9.3f')}  "
                 f"{num(summary['r_max_p95'], '9.3f')}  {summary['r_max_above_1']:>3}")
    here = sum(r.get("recorded_here", r["accepted"]) for r in summary["tasks"])
    if here < summary["accepted"]:
        lines.append(f"on this machine: {here} of the {summary['accepted']} accepted episodes (the others screened "
                     f"elsewhere; generate without --screen-only records them, the same bits)")
    again = summary.get("rerecorded") or {}
    if again.get("repeats"):
        n, seed = again["repeats"], again["r_max_largest_difference_seed"]
        lines.append(f"recorded again: {n}; first verdict kept {again['same_verdict']}/{n}, step count "
                     f"{again['same_steps']}/{n}, R_max the same bits {again['r_max_equal']}/{n}"
                     + ("" if seed is None else f", largest R_max difference "
                        f"{again['r_max_largest_difference']:.2g} (seed {seed})")
                     + (f", diverged (NaN R_max) in one run only {again['r_max_nan_once']}"
                        if again.get("r_max_nan_once") else ""))
    return "\n".join(lines)


def render_observations(trajectory_h5: Path, out_h5: Path, suite: str, task_id: int, obs_mode: str,
                        camera_size: tuple[int, int] | None = None, progress=None) -> tuple[int, int]:
    """Re-render stored episodes into ``obs_mode`` observations on the same 20 Hz timeline, the
    cameras at ``camera_size`` = (height, width) (None: 224x224). Rendering at the size a policy
    takes spends no raster time on pixels it would shrink away.

    Every recorded env state (reset + one per step) is restored and observed in order, so the
    cameras, the tactile images (whose shear tracking follows the episode) and the actions share
    one timeline with no resampling; the file is written by
    :func:`~mani_skill_softvt.data.trajectory.write_rendering`, which keeps the episodes an earlier
    ``out_h5`` already holds and, rendering ten episodes to a part file, those of a run killed
    mid-task. The states are restored, not re-simulated (ManiSkill's
    ``replay_trajectory --use-env-states`` steps the physics before each restore). Returns the
    episodes in the file and how many were rendered now; ``progress(1)`` per episode.
    """
    env = None
    spec = get_suite(suite)
    touch_of_twins = spec.rigid and spec.frames_tactile_model(obs_mode) is not None

    def observe(seed: int, states: dict) -> list[dict]:
        nonlocal env
        if touch_of_twins and TWIN_CONTACT_STATE not in states:
            # PhysX has no contacts for a restored state: the pinched twin would show a blank gel.
            raise ValueError(f"{trajectory_h5}: seed {seed} was recorded before the rigid twins' contact wrenches "
                             f"were part of the env state, so its touch cannot be rendered; record the demos again "
                             f"(move the episode files aside: 'python -m mani_skill_softvt.demos generate --suite "
                             f"{suite}' records the seeds its QC logs list)")
        if env is None:
            env = make_env(suite, task_id, dsr=False, obs_mode=obs_mode, camera_size=camera_size)
        env.reset(seed=seed)
        frames = []
        for t in range(len(next(iter(states.values())))):
            env.unwrapped.set_state_dict(state_dict_at(states, t))
            frames.append(flatten_batch(env.unwrapped.get_obs()))
        return frames

    try:
        return write_rendering(trajectory_h5, out_h5, obs_mode, observe, camera_sensor_configs(camera_size),
                               CURRENT_RENDER_KEYS.get(obs_mode, ()), progress,
                               tactile_model=get_suite(suite).frames_tactile_model(obs_mode))
    finally:
        if env is not None:
            env.close()


def _render_task(suite: str, task_id: int, out: str, obs_mode: str, camera_size, queue) -> tuple[int, int, int]:
    """One task's rendering (a work item of :func:`~mani_skill_softvt.parallel.run_tasks`): the
    task, its episodes, how many were rendered now (the rest were current); one message per episode."""
    demo_set = DemoSet(Path(out), suite)
    src, dst = demo_set.trajectory(task_id), demo_set.rendered(task_id, obs_mode, camera_size)
    with demo_set.task_lock(task_id):
        if _task_rendered(demo_set, task_id, obs_mode, camera_size):  # by another run meanwhile
            episodes = _episodes(src)
            for _ in range(episodes):
                queue.put(1)
            return task_id, episodes, 0
        return task_id, *render_observations(src, dst, suite, task_id, obs_mode, camera_size, progress=queue.put)


def _task_rendered(demo_set: DemoSet, task_id: int, obs_mode: str, camera_size) -> bool:
    """Whether the task's rendering in ``obs_mode`` at ``camera_size`` is current (:func:`rendering_is_current`);
    a twin's touch rendered from states without its contact wrenches (a blank gel) never is."""
    suite = get_suite(demo_set.suite)
    if suite.rigid and suite.frames_tactile_model(obs_mode) is not None and demo_set.trajectory(task_id).exists():
        with open_h5(demo_set.trajectory(task_id)) as f:
            if not all(holds_twin_contact(f[k]) for k in f.keys()):
                return False
    return rendering_is_current(demo_set.trajectory(task_id), demo_set.rendered(task_id, obs_mode, camera_size),
                                CURRENT_RENDER_KEYS.get(obs_mode, ()), suite.frames_tactile_model(obs_mode))


def _episodes(trajectory_h5: Path) -> int:
    with open_h5(trajectory_h5) as f:
        return len(f.keys())


def rendering_is_current(trajectory_h5: Path, rendered_h5: Path, needed: tuple[str, ...] = (),
                         tactile_model: int | None = None) -> bool:
    """Whether ``rendered_h5`` holds exactly the episodes of ``trajectory_h5``, each rendered from
    the same states (:func:`~mani_skill_softvt.data.trajectory.rendering_current`: the source's
    digest, the ``needed`` observation keys, frames of ``tactile_model`` if given); a re-run of
    render skips such a task."""
    if not rendered_h5.exists():
        return False
    try:
        with h5py.File(trajectory_h5, "r") as a, h5py.File(rendered_h5, "r") as b:
            return set(a.keys()) == set(b.keys()) and all(
                rendering_current(b[k], episode_digest(a[k]), needed, tactile_model) for k in a.keys())
    except OSError:  # unreadable: render it again
        return False


# Observation keys a rendering must have to count as current (older renderings lack the depth map).
CURRENT_RENDER_KEYS = {"rgb+tactile": tuple(tactile_keys(("depth",)))}


_OUT_HELP = (f"demos directory, generate + render output (default {DEMOS_DIR}: $SOFTVT_DEMOS_DIR, else the "
             "checkout's demos/; needed to generate or render when the package is installed)")


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.demos", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    g = sub.add_parser("generate", help="record expert demonstrations")
    g.add_argument("--suite", default="object_soft", choices=sorted(SUITES))
    g.add_argument("--tasks", nargs="+", default=["all"])
    g.add_argument("--num", type=int, default=100, help="training seeds per task (paper: 100 demos); with "
                   "--accepted, the most seeds a task may draw")
    g.add_argument("--accepted", type=int, default=None, metavar="N",
                   help="draw training seeds in order until N demos of each task are accepted (at most --num seeds)")
    g.add_argument("--screen-only", action="store_true",
                   help="record only seeds the QC logs do not list, keep their verdicts for accepted episodes that "
                        "are not on this machine, merge nothing: grows the set's QC logs; run again without it "
                        "on the machine that trains (it records the listed episodes, the same bits, and merges)")
    g.add_argument("--workers", type=int, default=1)
    g.add_argument("--ray", metavar="ADDRESS", default=None,
                   help="run the tasks on Ray instead of --workers processes: 'local', 'auto' or ray://host:10001")
    g.add_argument("--out", type=Path, default=None, help=_OUT_HELP)
    g.add_argument("--planner", choices=("mplib", "cartesian"), default=None,
                   help="how the expert joins its waypoints (default: mplib motion planning)")
    g.add_argument("--control-mode", default="pd_ee_pose",
                   choices=("pd_ee_pose", "pd_ee_pose_binary", "pd_joint_pos", "pd_joint_pos_binary"),
                   help="recorded actions: the paper's pd_ee_pose (default) or ManiSkill's pd_joint_pos "
                        "(python -m mani_skill_softvt.replay -c converts it into any other mode)")
    r = sub.add_parser("render", help="re-render stored demos into observations (e.g. rgb+tactile)")
    r.add_argument("--suite", default="object_soft", choices=sorted(SUITES))
    r.add_argument("--tasks", nargs="+", default=["all"])
    r.add_argument("--obs-mode", default="rgb+tactile",
                   help="any camera mode of the env (mani_skill_softvt.observations), e.g. rgb+tactile, rgbd+tactile "
                        "(camera depth, which export-lerobot carries as observation.depth.<camera>), pointcloud")
    r.add_argument("--camera-size", default="native", metavar="HxW",
                   help="render both cameras at HxW (e.g. 84x84, the cpu baselines' input) instead of 224x224")
    r.add_argument("--workers", type=int, default=1, help="tasks rendered in parallel processes")
    r.add_argument("--out", type=Path, default=None, help=_OUT_HELP)
    s = sub.add_parser("stats", help="per-task statistics of generated demos")
    s.add_argument("--suite", default="object_soft", choices=sorted(SUITES))
    s.add_argument("--out", type=Path, default=None, help=_OUT_HELP)
    e = sub.add_parser("export-lerobot", help="export rendered demos to LeRobot's dataset v3.0 layout (parquet + mp4)")
    e.add_argument("--suite", default="object_soft", choices=sorted(SUITES))
    e.add_argument("--tasks", nargs="+", default=["all"], help="'all': every task with demos under --out")
    e.add_argument("--out", type=Path, default=None, help=_OUT_HELP)
    e.add_argument("--lerobot-out", type=Path, required=True, help="new (empty) directory for the LeRobot dataset")
    e.add_argument("--obs-mode", default="rgb+tactile", help="which rendering to export (as passed to render)")
    e.add_argument("--camera-size", default="native", metavar="HxW", help="which rendering to export (as passed to render)")
    e.add_argument("--image-size", default="224x224", metavar="HxW",
                   help="resize every image stream (cameras and tactile) to HxW, as LeRobot's Diffusion Policy "
                        "needs one shape for all image inputs; 'native' keeps each stream's size (tactile 240x320)")
    e.add_argument("--no-video", action="store_true", help="omit the image features (no mp4), e.g. for a tiny sample")
    return ap


def main(argv=None):
    ap = _parser()
    args = ap.parse_args(argv)
    if args.out is None:
        args.out = DEMOS_DIR
        if args.cmd in ("generate", "render"):  # they write there: never by default into an installed package
            try:
                writable_default(DEMOS_DIR, "--out", "SOFTVT_DEMOS_DIR")
            except ValueError as err:
                ap.error(str(err))
    command = {"generate": _generate, "render": _render, "export-lerobot": _export_lerobot, "stats": _stats}
    return command[args.cmd](ap, args)


def _generate(ap: argparse.ArgumentParser, args) -> dict:
    tasks = list(range(NUM_TASKS)) if args.tasks == ["all"] else [int(t) for t in args.tasks]
    if args.num < 1 or args.workers < 1:
        ap.error("--num and --workers must be >= 1")
    try:
        report = generate(args.suite, tasks, args.num, args.out, args.workers, ray_address=args.ray,
                          planner=args.planner, control_mode=args.control_mode, accepted=args.accepted,
                          screen_only=args.screen_only)
    except ValueError as err:  # a bad --accepted, or a set recorded under other physics or actions
        ap.error(str(err))
    for r in report["tasks"]:
        print(f"task {r['task_id']}: {r['accepted']}/{r['generated']} accepted, {r['seconds_per_demo']:.1f} s/demo"
              + (f", rejected: {r['rejected']}" if r["rejected"] else ""))
        if args.accepted is not None and r["accepted"] < args.accepted:
            print(f"task {r['task_id']}: {args.num} seeds drew only {r['accepted']} of the {args.accepted} accepted "
                  f"demos asked for; run again with a larger --num (it resumes)")
    return report


def _render(ap: argparse.ArgumentParser, args) -> None:

    if args.workers < 1:
        ap.error("--workers must be >= 1")
    try:
        camera_size = parse_image_size(args.camera_size, "--camera-size")
        camera_sensor_configs(camera_size)
        if not ObsMode.parse(args.obs_mode).images:
            raise ValueError(f"--obs-mode {args.obs_mode}: a rendering is of camera images; give a camera mode "
                             "(rgb+tactile, rgbd+tactile, pointcloud...)")
    except ValueError as err:
        ap.error(str(err))
    demo_set = DemoSet(args.out, args.suite)
    tasks = list(range(NUM_TASKS)) if args.tasks == ["all"] else [int(t) for t in args.tasks]
    todo = []
    for t in tasks:
        src, dst = demo_set.trajectory(t), demo_set.rendered(t, args.obs_mode, camera_size)
        if not src.exists():
            print(f"task {t}: no demos at {src}; run generate first")
        elif _task_rendered(demo_set, t, args.obs_mode, camera_size):
            print(f"task {t}: already rendered (delete {dst.name} to redo it)")
            shutil.rmtree(rendering_parts_dir(dst), ignore_errors=True)  # a run killed after its last pack
        else:
            todo.append((args.suite, t, str(args.out), args.obs_mode, camera_size))

    size = "" if camera_size is None else f" {camera_size_name(camera_size)}"
    try:
        episodes = sum(_episodes(demo_set.trajectory(item[1])) for item in todo)
        with tqdm(total=episodes, desc=f"render {args.obs_mode}{size}", unit="episode") as bar:
            for kind, value in run_tasks(_render_task, todo, args.workers):
                if kind == "message":
                    bar.update(value)
                elif kind == "result":
                    bar.write(f"task {value[0]}: {value[1]} episodes, {value[2]} rendered now, "
                              f"{value[1] - value[2]} kept from the previous rendering")
    except CorruptDataError as err:
        ap.error(str(err))
    return None


def _export_lerobot(ap: argparse.ArgumentParser, args) -> dict:
    demo_set = DemoSet(args.out, args.suite)
    tasks = demo_set.tasks_with_trajectories() if args.tasks == ["all"] else [int(t) for t in args.tasks]
    try:
        sources = demo_set.rendered_sources(tasks, args.obs_mode, parse_image_size(args.camera_size, "--camera-size"))
        info = export_lerobot(sources, args.lerobot_out,
                              use_videos=not args.no_video, image_size=parse_image_size(args.image_size))
    except (FileNotFoundError, ValueError, OSError) as err:  # OSError: CorruptDataError names the file
        ap.error(str(err))
    print(f"{args.lerobot_out}: {info['total_episodes']} episodes, {info['total_frames']} frames, "
          f"{info['total_tasks']} tasks (LeRobot {info['codebase_version']}, {info['fps']} fps)")
    return info


def _stats(ap: argparse.ArgumentParser, args) -> dict:
    try:
        summary = stats(args.suite, args.out)
    except FileNotFoundError as err:
        ap.error(str(err))
    print(format_stats(summary))
    demo_set = DemoSet(args.out, args.suite)
    print(f"written: {demo_set.stats}, {demo_set.r_max_histogram}")
    if summary["unreadable_files"]:
        print(f"{len(summary['unreadable_files'])} unreadable demo file(s):", *summary["unreadable_files"], sep="\n  ")
        raise SystemExit(1)
    return summary


if __name__ == "__main__":
    main()
