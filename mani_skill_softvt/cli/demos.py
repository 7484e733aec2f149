"""Expert demonstrations, the command: generate (resumable, parallel), merge into ManiSkill trajectories, stats.

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
from pathlib import Path

from ..data.demo_set import DemoSet
from ..data.trajectory import CorruptDataError
from ..demonstrations.generate import generate
from ..demonstrations.render import render
from ..demonstrations.stats import format_stats, stats
from ..integrations.lerobot.export import export_lerobot
from ..contracts.observations import CameraSize, ObsMode, parse_image_size
from ..paths import DEMOS_DIR, writable_default
from ..tasks.suites import NUM_TASKS, SUITES


_OUT_HELP = (f"demos directory, generate + render output (default {DEMOS_DIR}: $SOFTVT_DEMOS_DIR, else the "
             "checkout's demo-data/; needed to generate or render when the package is installed)")


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
                        "(python -m mani_skill_softvt.integrations.maniskill.replay -c converts it into any other mode)")
    r = sub.add_parser("render", help="re-render stored demos into observations (e.g. rgb+tactile)")
    r.add_argument("--suite", default="object_soft", choices=sorted(SUITES))
    r.add_argument("--tasks", nargs="+", default=["all"])
    r.add_argument("--obs-mode", default="rgb+tactile",
                   help="any camera mode of the env (mani_skill_softvt.contracts.observations), e.g. rgb+tactile, rgbd+tactile "
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
        camera_size = CameraSize.of(args.camera_size, "--camera-size")
        if not ObsMode.parse(args.obs_mode).images:
            raise ValueError(f"--obs-mode {args.obs_mode}: a rendering is of camera images; give a camera mode "
                             "(rgb+tactile, rgbd+tactile, pointcloud...)")
    except ValueError as err:
        ap.error(str(err))
    tasks = list(range(NUM_TASKS)) if args.tasks == ["all"] else [int(t) for t in args.tasks]
    try:
        render(args.suite, tasks, args.out, args.obs_mode, camera_size, args.workers)
    except CorruptDataError as err:
        ap.error(str(err))
    return None


def _export_lerobot(ap: argparse.ArgumentParser, args) -> dict:
    demo_set = DemoSet(args.out, args.suite)
    tasks = demo_set.tasks_with_trajectories() if args.tasks == ["all"] else [int(t) for t in args.tasks]
    try:
        sources = demo_set.rendered_sources(tasks, args.obs_mode, CameraSize.of(args.camera_size, "--camera-size"))
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
