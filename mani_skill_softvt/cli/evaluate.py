"""Closed-loop benchmark: TSR and DSR of a policy under the ID or OOD protocol.

    python -m mani_skill_softvt.cli.evaluate                          # small default: expert, 3 tasks, 1 episode each
    python -m mani_skill_softvt.cli.evaluate --suite spatial_soft --protocol ood --policy mypkg.policies:MyPolicy \\
        --obs-mode rgb+tactile --tasks all --episodes-per-task 50 --workers 2
    python -m mani_skill_softvt.cli.evaluate --tasks all --episodes-per-task 50 --ray ray://head:10001   # on Ray
    python -m mani_skill_softvt.cli.evaluate --rescore outputs/eval/object_soft_id_expert.jsonl --percentile 80
    python -m mani_skill_softvt.cli.evaluate --reproduce campaign-data/results/object_soft_id_vo-c-cpu.jsonl

Writes one JSONL record per episode (resumable), a markdown and JSON report, and plots of the
R_t traces (and, for OOD, TSR/DSR per factor). ``--rescore`` re-aggregates stored records at
another calibration percentile using the cards' sweep records: no new rollouts. ``--reproduce``
runs recorded episodes again (the first ``--episodes-per-task`` of each task, default 1) with the
configuration they were recorded with and compares the new records with the stored ones, field by
field (all but the wall time): exit status 0 if they are the same, 1 naming the fields that differ.
A record of a trained policy file carries the file's SHA-256; another file under that name is
refused before anything runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from ..calibration.cards import load_calibration_card
from ..evaluation.metrics import rescore_record
from ..evaluation.protocols import PROTOCOLS
from ..evaluation.sidecar import sidecar
from ..evaluation.records import RecordIntegrityError, read_records
from ..evaluation.report import plot_ood_curves, plot_traces, write_report
from ..evaluation.run import DEFAULT_TASKS, RunConfig, task_ids
from ..evaluation.runner import evaluate, recorded_obs_modes, relative_difference, reproduce, run_records
from ..evaluation.videos import record_episode_video, video_name
from ..contracts.observations import CameraSize
from ..provenance.numerics import numerics_of, reproduction_note
from ..provenance.stack import MACHINE_KEYS, software_stack, stack_differences, unrecorded
from ..tasks.suites import SUITES, task_spec
from .arguments import existing_path


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.cli.evaluate", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--suite", default="object_soft", choices=sorted(SUITES))
    ap.add_argument("--protocol", default="id", choices=list(PROTOCOLS),
                    help="id (the paper's), ood (its nine conditions), side_swap (Spatial suites: the ID episode "
                         "with the instruction naming the other instance; not the paper's), placement_x2 (the ID "
                         "episodes with the placement ranges doubled: the difficulty study)")
    ap.add_argument("--policy", default="expert",
                    help="expert | expert_cartesian | hold | random | module:Class (imports and runs that code "
                         "in this process) | ws://HOST:PORT (a policy server speaking openpi's protocol; "
                         "needs an obs mode with rgb: rgb, rgbd, each +tactile) | PATH/policy.pt (a trained Diffusion Policy "
                         "baseline, softvt-train)")
    ap.add_argument("--tasks", nargs="+", default=None,
                    help=f"task ids, or 'all' (default {' '.join(map(str, DEFAULT_TASKS))}; with --reproduce, default and 'all' are "
                         "every task the file holds)")
    ap.add_argument("--episodes-per-task", type=int, default=None, help="default 1")
    ap.add_argument("--conditions", nargs="+", default=None, help="OOD conditions (default: all nine)")
    ap.add_argument("--obs-mode", default=None,
                    help="any mode the env supports (mani_skill_softvt.contracts.observations: state, state_dict, rgb, depth, "
                         "segmentation, rgbd, pointcloud, sensor_data, '+' combinations, each camera mode with "
                         "+tactile); default: the policy's own (a trained baseline's, a policy class's obs_modes), "
                         "else the env's, state")
    ap.add_argument("--camera-size", default=None, metavar="HxW",
                    help="render the cameras at HxW (default: the size the policy asks for, a trained baseline's "
                         "own, else 224x224); a policy server trained on smaller images needs it")
    ap.add_argument("--control-mode", default=None,
                    help="any mode the env offers (mani_skill_softvt.contracts.actions CONTROL_MODES): pd_ee_pose (default), "
                         "pd_ee_pose_binary (the binary-gripper baselines vo-b, vt-b; their default), ManiSkill's "
                         "pd_joint_pos, pd_joint_delta_pos, pd_ee_delta_pose (a ManiSkill diffusion-policy "
                         "checkpoint's default, evaluation/maniskill_dp.py) and their _binary twins")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--ray", metavar="ADDRESS", default=None,
                    help="run the episodes on Ray instead of --workers processes: 'local', 'auto' or ray://host:10001")
    ap.add_argument("--out", type=Path, default=Path("outputs/eval"))
    ap.add_argument("--rescore", type=Path, default=None, help="records (JSONL) to re-aggregate at --percentile")
    ap.add_argument("--percentile", type=float, default=None)
    ap.add_argument("--reproduce", type=Path, default=None, metavar="RECORDS",
                    help="run recorded episodes again and compare (see above); exit status 1 if they differ")
    ap.add_argument("--video", type=int, default=0, metavar="N",
                    help="re-run the first N episodes in rgb+tactile mode and write <out>/videos/*.mp4")
    args = ap.parse_args(argv)

    if args.rescore is not None:
        return _rescore(existing_path(args.rescore, "--rescore"), args.percentile, args.out)
    if args.reproduce is not None:
        given = [f for f, v in (("--policy", args.policy != "expert"), ("--obs-mode", args.obs_mode), ("--ray", args.ray),
                                ("--control-mode", args.control_mode), ("--camera-size", args.camera_size)) if v]
        if given:
            ap.error(f"--reproduce runs the records' own policy and configuration; drop {', '.join(given)}")
        return _reproduce(ap, existing_path(args.reproduce, "--reproduce"), args.episodes_per_task or 1, args.workers,
                          args.tasks)
    if args.video < 0:
        ap.error("--video must be >= 0")
    def resolve(obs_mode):
        return RunConfig.resolve(args.policy, obs_mode, args.control_mode,
                                 None if args.camera_size is None else CameraSize.of(args.camera_size, "--camera-size"),
                                 suite=args.suite, protocol=args.protocol, tasks=args.tasks or DEFAULT_TASKS,
                                 episodes_per_task=1 if args.episodes_per_task is None else args.episodes_per_task,
                                 conditions=args.conditions)

    try:
        run = resolve(args.obs_mode)
        # No --obs-mode: a run the records file holds in another mode (made when the default was
        # another) is resumed in its mode, not started again beside it.
        records_file = args.out / f"{run.stem}.jsonl"
        modes = set() if args.obs_mode else recorded_obs_modes(records_file, run)
        if len(modes) == 1 and run.obs_mode not in modes:
            try:  # only a run this policy can run in that mode, and whose records it would resume
                recorded = resolve(next(iter(modes)))
            except (ValueError, FileNotFoundError):
                recorded = None
            if recorded is not None and run_records(records_file, recorded):
                run = recorded
                print(f"note: resuming the run {records_file} holds, in obs mode {run.obs_mode} "
                      "(give --obs-mode to start another run)")
    except (ValueError, FileNotFoundError) as e:
        ap.error(str(e))
    if args.workers < 1:
        ap.error("--workers must be >= 1")
    if args.video and run.obs_mode not in ("state_dict", "rgb", "rgb+tactile") and args.policy != "expert":
        ap.error(f"--video re-runs episodes with dict observations (rgb+tactile), which a policy evaluated in "
                 f"obs mode '{run.obs_mode}' does not read; evaluate with state_dict, rgb or rgb+tactile")
    if run.policy.kind == "class":
        print(f"note: --policy {args.policy} imports and runs that module's code in the evaluation processes")
    records_file = args.out / f"{run.stem}.jsonl"
    bar = tqdm(total=len(run.episodes()), desc=f"{run.suite} {run.protocol}", unit="episode")
    try:
        records = evaluate(run, records_file, workers=args.workers, progress=bar.update, ray_address=args.ray)
    except ValueError as e:
        ap.error(str(e))
    bar.close()
    failed = [r for r in records if r["termination"] in ("policy_error", "worker_died")]
    if failed:
        print(f"{len(failed)} episode(s) ended in an error, recorded as failures; the first: {failed[0]['error']}")
    md, _ = write_report(records, args.out, run.stem)
    plot_traces(records, args.out / f"{run.stem}_traces.png")
    if run.protocol == "ood":
        id_run = run.with_protocol("id")
        id_records = list(run_records(args.out / f"{id_run.stem}.jsonl", id_run).values())
        plot_ood_curves(records, id_records, args.out / f"{run.stem}_ood.png")
    print(md.read_text())
    if records and records[0]["receipt"]["privileged"]:
        print("(policy is privileged: it reads the simulator state)")
    print(f"records: {records_file}  report: {md}")
    if args.video:
        _videos(records[:args.video], run, args.out / "videos")
    return {"records": records}


def _reproduce(ap: argparse.ArgumentParser, path: Path, per_task: int, workers: int, tasks: list[str] | None) -> dict:
    if not Path(path).is_file():
        ap.error(f"--reproduce: {path} does not exist")
    bar = tqdm(desc=f"reproduce {Path(path).name}", unit="episode")
    try:
        results = reproduce(path, per_task, workers, progress=bar.update, tasks=None if tasks in (None, ["all"]) else task_ids(tasks))
    except (ValueError, RecordIntegrityError, FileNotFoundError) as e:
        ap.error(str(e))
    bar.close()
    differing = [r for r, _, fields in results if fields]
    for r, new, fields in results:
        where = f"{r['suite']} task {r['task_id']} {r['condition']} seed {r['seed']}"
        gaps = [(f, relative_difference(r.get(f), new.get(f)) if new is not None and "." not in f else None) for f in fields]
        named = [f if gap is None else f"{f} (by at most {gap:.1e} relative)" for f, gap in gaps]
        print(f"{where}: {'differs in ' + ', '.join(named) if fields else 'the same, bit for bit'}")
    named = bool(results) and bool(results[0][0]["receipt"].get("numerics"))
    known = sidecar(path)
    print(f"{len(results) - len(differing)} of {len(results)} episodes of {path} reproduced (numerics "
          f"{numerics_of(results[0][0], known) if results else '-'}, "
          f"{'as the records name them' if named else 'as machines of their kind ran before the pins'})")
    note = reproduction_note(results[0][0], software_stack(), known) if results else None
    if note:
        print(note)
    other = stack_differences(results[0][0]["receipt"].get("stack"), software_stack()) if results else []
    # The machine's kind is said above; under pinned numerics it does not choose the bits at all.
    other = [d for d in other if d.split()[0] not in MACHINE_KEYS]
    unknown = unrecorded(other)
    mismatched = [d for d in other if not d.endswith(" unrecorded")]
    if mismatched:
        print(f"the records were made on another stack ({'; '.join(mismatched)}): the same episode keeps its outcome "
              "there, not its bits, so compare rates rather than records")
    if unknown:
        print(f"the records do not name their {', '.join(unknown)} (kept only since they were made): if they differ, "
              "the machine that made them may have differed there")
    elif results and "stack" not in results[0][0]["receipt"]:
        print("the records predate the stack being recorded: if they differ, compare the stack they were made on "
              "(docs/evaluation.md) with this one")
    if differing:
        raise SystemExit(1)
    return {"reproduced": len(results)}


def _rescore(path: Path, percentile: float | None, out: Path) -> dict:
    if percentile is None:
        raise SystemExit("--rescore needs --percentile")
    if not Path(path).exists():
        raise SystemExit(f"--rescore: {path} does not exist")
    try:
        records = read_records(path)  # every record verified against its hash
    except ValueError as e:  # RecordIntegrityError, or a line that is not JSON: one line naming file and line
        raise SystemExit(f"--rescore: {e}") from None
    if not records:
        raise SystemExit(f"no records in {path}")
    new = []
    for r in records:
        card = load_calibration_card(task_spec(r["suite"], int(r["task_id"])).soft_asset_id)
        new.append(rescore_record(r, card.at_percentile(percentile)["tau_o"]))
    md, _ = write_report(new, out, f"{path.stem}_p{percentile:g}")
    print(md.read_text())
    return {"records": new}


def _videos(records: list[dict], run: RunConfig, out: Path) -> None:
    """Videos of ``records`` (re-run in rgb+tactile mode); existing files are kept, so a re-run resumes."""
    for r in records:
        path = out / video_name(run.stem, r)
        if not path.exists():
            record_episode_video(r, run, path)
        print(f"video: {path}")


if __name__ == "__main__":
    main()
