"""ManiSkill's motion-planning demo generation for the SoftVT tasks.

A drop-in for ``python -m mani_skill.examples.motionplanning.panda.run`` (which knows only
ManiSkill's own tasks): the same flags, the same output, the scripted expert as the solution
(:func:`mani_skill_softvt.expert.solution.solve`)::

    python -m mani_skill_softvt.integrations.maniskill.motionplanning -e SoftVTObjectSoft-Task3-v1 -n 10 --only-count-success
    python -m mani_skill_softvt.integrations.maniskill.motionplanning -e SoftVTObjectRigid-v1 --task-id 3 -n 2 --save-video

``-e`` takes a task's own env id (``SoftVTObjectSoft-Task3-v1``) or a suite's with ``--task-id``.
Writes ``<record-dir>/<task env id>/motionplanning/<traj-name>.h5`` + ``.json`` (e.g.
``demos/SoftVTObjectSoft-Task3-v1/motionplanning/task3.h5``) with ManiSkill's ``RecordEpisode``
(``source_type="motionplanning"``, actions in ``pd_joint_pos`` unless ``--control-mode`` says
otherwise, its gripper ManiSkill's normalised action), plus the evaluator stream and episode
metadata (:mod:`mani_skill_softvt.data.record`); the json names the env
``mani_skill_softvt:<task env id>``. Replay or convert it with ``python -m mani_skill_softvt.integrations.maniskill.replay``.
Seeds are the task's training seeds (:func:`mani_skill_softvt.data.seeds.train_seed`), disjoint
from the evaluation seeds. The benchmark's own ``python -m mani_skill_softvt.demos generate`` runs
the same solution with the same recorder, one resumable file per episode.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
from pathlib import Path

import gymnasium as gym
import numpy as np
from mani_skill.trajectory.merge_trajectory import merge_trajectories
from tqdm import tqdm

from ...data.record import SoftVTRecordEpisode, quiet_maniskill_logger
from ...data.seeds import train_seed
from ...evaluation.wrapper import DSRWrapper
from ...expert.solution import SOURCE_DESC, solve
from ...contracts.observations import info_bool
from ...parallel import run_tasks
from ...tasks import constants as C
from ...contracts.observations import ObsMode
from ...contracts.actions import CONTROL_MODES
from ...tasks.suites import SUITES, parse_env_id, task_spec


def parse_args(argv=None, ap: argparse.ArgumentParser | None = None):
    """The checked arguments (:func:`check_args`); a bad value exits as an argparse error does."""
    ap = ap or parser()
    args = ap.parse_args(argv)
    try:
        check_args(args)
    except ValueError as e:
        ap.error(str(e))
    return args


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m mani_skill_softvt.integrations.maniskill.motionplanning", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-e", "--env-id", default="SoftVTObjectSoft-v1",
                    help="a task's env id (SoftVTObjectSoft-Task3-v1), or a suite's (SoftVTObjectSoft-v1) with "
                         "--task-id; either may be prefixed mani_skill_softvt:")
    ap.add_argument("--task-id", type=int, default=None, help="task of the suite (0-9; default: the env id's, else 0)")
    ap.add_argument("-o", "--obs-mode", default="none",
                    help="observations to record (default none: replay into any obs mode later)")
    ap.add_argument("-n", "--num-traj", type=int, default=10, help="number of trajectories to generate")
    ap.add_argument("--only-count-success", action="store_true",
                    help="generate until num-traj successful trajectories; save only those")
    ap.add_argument("--reward-mode", default=None)
    ap.add_argument("-b", "--sim-backend", default="auto", help="'auto' or 'physx_cpu' (SoftVT runs on the CPU)")
    ap.add_argument("--render-mode", default="rgb_array", help="'rgb_array' or 'sensors': what the videos show")
    ap.add_argument("--vis", action="store_true", help="show the solution live in SAPIEN's viewer")
    ap.add_argument("--save-video", action="store_true")
    ap.add_argument("--traj-name", default=None, help="name of the .h5 (default: task<task-id>)")
    ap.add_argument("--shader", default="default")
    ap.add_argument("--record-dir", default="demos")
    ap.add_argument("--num-procs", type=int, default=1, help="processes, each with its own env (one core each)")
    ap.add_argument("--control-mode", default="pd_joint_pos",
                    help="recorded action space: pd_joint_pos (ManiSkill's), pd_ee_pose (the paper's) or a _binary twin")
    ap.add_argument("--planner", choices=("mplib", "cartesian"), default="mplib")
    ap.add_argument("--start-index", type=int, default=0, help="first training-seed index")
    ap.add_argument("--max-tries", type=int, default=None, metavar="N",
                    help="with --only-count-success, stop after N seeds per process (default 20 per trajectory): "
                         "an expert that keeps failing ends the run with what it saved instead of looping")
    return ap


def check_args(args) -> None:
    """Resolve ``-e``/``--task-id`` into the task's own env id (``args.env_id``, bare) and check the
    modes, before any process starts; a ValueError names the bad value and what to pass."""
    suite, task_id = parse_env_id(args.env_id)
    if task_id is not None and args.task_id not in (None, task_id):
        raise ValueError(f"-e {args.env_id} is task {task_id}, but --task-id {args.task_id} was passed; "
                         f"pass -e {SUITES[suite].env_id} --task-id {args.task_id}, or drop --task-id")
    task_id = task_id if task_id is not None else (0 if args.task_id is None else args.task_id)
    task_spec(suite, task_id)  # validates the task id
    args.suite, args.task_id, args.env_id = suite, task_id, SUITES[suite].task_env_id(task_id)
    modes = [m for m in CONTROL_MODES if m.removesuffix("_binary") in ("pd_joint_pos", "pd_ee_pose")]
    if args.control_mode not in modes:
        raise ValueError(f"--control-mode {args.control_mode}: the expert records one of {modes}; record in "
                         f"pd_joint_pos and convert with `python -m mani_skill_softvt.integrations.maniskill.replay --traj-path FILE.h5 -c "
                         f"{args.control_mode}`")
    try:
        ObsMode.parse(args.obs_mode)  # the env's modes (mani_skill_softvt.contracts.observations)
    except ValueError as e:
        raise ValueError(f"-o: {e}") from None


def make_recorder(env_id: str, task_id: int, output_dir: Path, traj_name: str, *, obs_mode: str = "none",
                  control_mode: str = "pd_joint_pos", render_mode: str = "rgb_array", save_video: bool = False,
                  reward_mode: str | None = None, shader: str = "default", sim_backend: str = "auto"):
    """A DSR-wrapped SoftVT env inside :class:`~mani_skill_softvt.data.record.SoftVTRecordEpisode`,
    recording ``<output_dir>/<traj_name>.h5`` as ManiSkill's runner does (no save on reset)."""
    kwargs = dict(task_id=task_id, obs_mode=obs_mode, control_mode=control_mode, render_mode=render_mode,
                  sim_backend=sim_backend, sensor_configs=dict(shader_pack=shader),
                  human_render_camera_configs=dict(shader_pack=shader))
    if reward_mode is not None:
        kwargs["reward_mode"] = reward_mode
    env = DSRWrapper(gym.make(env_id, **kwargs))
    return SoftVTRecordEpisode(env, output_dir=str(output_dir), trajectory_name=traj_name, save_video=save_video,
                               source_type="motionplanning", source_desc=SOURCE_DESC, video_fps=C.CONTROL_FREQ,
                               record_reward=False, save_on_reset=False)


def _run(args, first: int, stride: int, count: int, traj_name: str, queue) -> str:
    """Record ``count`` trajectories into one file, from the training seeds with indices ``first``,
    ``first + stride``, ... (more of them on failures with --only-count-success; processes take
    interleaved indices, so they never share a seed); puts per-trajectory progress on ``queue``."""
    output_dir = Path(args.record_dir) / args.env_id / "motionplanning"
    env = make_recorder(args.env_id, args.task_id, output_dir, traj_name, obs_mode=args.obs_mode,
                        control_mode=args.control_mode, render_mode=args.render_mode, save_video=args.save_video,
                        reward_mode=args.reward_mode, shader=args.shader, sim_backend=args.sim_backend)
    index, saved, tries = first, 0, 0
    max_tries = args.max_tries or 20 * count
    while saved < count and tries < max_tries:
        tries += 1
        seed = train_seed(args.task_id, index)  # raises past the training range
        index += stride
        try:
            res = solve(env, seed=seed, vis=args.vis, planner=args.planner)
        except Exception as e:  # noqa: BLE001  (an episode's failure is a result, as in ManiSkill's runner)
            print(f"seed {seed}: no valid solution: {e}")
            res = -1
        # A collapsed tet makes a demo unusable, as a crash of the episode once did (docs/evaluation.md).
        success = res != -1 and info_bool(res[-1], "success") and not env.get_wrapper_attr("collapsed_steps")
        queue.put(("tried", success))
        if args.only_count_success and not success:
            env.flush_trajectory(save=False)
            if args.save_video:
                env.flush_video(save=False)
            continue
        env.flush_trajectory()
        if args.save_video:
            env.flush_video()
        saved += 1
        queue.put(("saved", success))
    env.close()
    return str(output_dir / f"{traj_name}.h5")


def main(argv=None) -> dict:
    ap = parser()
    args = parse_args(argv, ap)
    if args.num_traj < 1 or args.num_procs < 1 or (args.max_tries is not None and args.max_tries < 1):
        ap.error("-n, --num-procs and --max-tries must be >= 1")
    name = args.traj_name or f"task{args.task_id}"
    out = Path(args.record_dir) / args.env_id / "motionplanning" / f"{name}.h5"
    if out.exists():
        ap.error(f"{out} exists; pass another --traj-name or move it away (nothing was overwritten)")
    try:  # an unwritable --record-dir fails here, named, not in a worker
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        ap.error(f"cannot create {out.parent} ({e.strerror}); pass a writable --record-dir")
    procs = min(args.num_procs, args.num_traj)
    counts = [len(c) for c in np.array_split(np.arange(args.num_traj), procs)]
    items = [(args, args.start_index + k, procs, n, name if procs == 1 else f"{name}.{k}")
             for k, n in enumerate(counts)]
    tried = succeeded = saved = 0
    paths = []
    with tqdm(total=args.num_traj, desc=f"motion planning {args.env_id} task {args.task_id}", unit="traj") as bar:
        for kind, value in run_tasks(_run, items, workers=procs):
            if kind == "message":
                event, success = value
                if event == "tried":
                    tried += 1
                    succeeded += success
                    bar.set_postfix(success_rate=f"{succeeded / tried:.2f}")
                else:
                    saved += 1
                    bar.update()
            else:
                paths.append(value)
    if procs > 1:
        with quiet_maniskill_logger():
            merge_trajectories(str(out), sorted(paths))
        for p in paths:
            os.remove(p)
            os.remove(p.replace(".h5", ".json"))
    print(f"{out}: {saved} trajectories, expert success {succeeded}/{tried}")
    if saved < args.num_traj:
        print(f"the expert succeeded on {saved} of the {args.num_traj} trajectories asked for within --max-tries; "
              "where it keeps failing, see docs/demos.md (under NumPy 2 the mplib planner is refused and the "
              "Cartesian plan is used: make demos on the default stack)")
    return {"path": str(out), "tried": tried, "succeeded": succeeded, "saved": saved}


def cli() -> None:
    """The console command (``softvt-motionplanning``): Warp needs spawned workers, as under ``python -m``."""
    mp.set_start_method("spawn", force=True)
    main()


if __name__ == "__main__":
    cli()
