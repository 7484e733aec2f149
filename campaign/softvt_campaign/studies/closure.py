"""How trained policies close the gripper over an episode, beside the expert's closure for the same seed.

    python -m softvt_campaign.studies.closure campaign-data/policies/vo-c-cpu.pt \
        campaign-data/policies/vt-c-cpu.pt --task 3 --episodes 6 --out campaign-data/results
    python -m softvt_campaign.studies.closure campaign-data/policies/object_rigid/vo-c-cpu.pt \
        --suite object_rigid --task 7 --episodes 10 --demos $SOFTVT_DEMOS_DIR --out campaign-data/results

The scripted expert draws one closure per episode, uniform in the object's calibrated envelope
[g_min, g_max], and commands it at once for the whole hold (``expert.pick_place``). A learned
policy commands its closure afresh in every chunk. This runs each policy (one worker each, one
BLAS thread, as evaluation workers do) on the first ``--episodes`` ID seeds of a task through the
evaluator's own episode (:func:`~mani_skill_softvt.evaluation.runner.run_episode`), and keeps
every step's commanded closure (the action's gripper column), whether the object was held, and
the force on the weaker pad.
Each episode's record is checked against the policy's committed ID records in ``--records``
(``evaluate``'s files), which it must match bit for bit (exit status 1 if not, as ``evaluate
--reproduce``); for records made on another stack it also says what differs and whether the
outcomes held.

It writes ``closure_<suite>_task<T>.json`` (the closures, R_t, the summaries below, each policy's
SHA-256) and ``closure_<suite>_task<T>.png`` (closure and R_t over time, one column per policy; the
expert's draw for each seed dashed), and prints per episode the closure of the first and last
chunks that held the object, their spread, the closure commanded when the object left the hand
and the pad force just before and then (a force that drops to 0 there: the fingers opened).

What a policy can know of its own closure: once the fingers stop on the object, the jaw width in
its state is the only proprioceptive trace of how hard it squeezes. On a soft object the width
falls as the closure rises; on a rigid twin it stays at the object's width whatever the closure.
``--demos`` measures that readout in the demonstrations the policy learned from (each demo's
closure against its held jaw width, :func:`closure_readout`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from tqdm import tqdm

from ..baselines.agent import GRIPPER
from mani_skill_softvt.data.demo_set import DemoSet
from mani_skill_softvt.data.seeds import ID_EPISODES_PER_TASK
from mani_skill_softvt.data.trajectory import open_h5
from mani_skill_softvt.evaluation.protocols import episode_key
from mani_skill_softvt.evaluation.report import rt_series
from mani_skill_softvt.evaluation.run import RunConfig, policy_tag
from mani_skill_softvt.evaluation.runner import record_differences, run_episode, run_records
from mani_skill_softvt.evaluation.wrapper import make_env
from mani_skill_softvt.expert.pick_place import draw_closure
from mani_skill_softvt.fileio import atomic_write, atomic_write_json
from mani_skill_softvt.parallel import run_tasks
from mani_skill_softvt.physics.constants import CONTROL_FREQ
from mani_skill_softvt.rollout import EvaluatorTrace, Observer
from mani_skill_softvt.provenance.stack import software_stack, stack_differences
from mani_skill_softvt.tasks.suites import NUM_TASKS, SUITES


OUTCOME_FIELDS = ("termination", "success", "dsr_success")  # what an episode keeps on another machine


def held_chunks(closure, held, chunk: int) -> np.ndarray:
    """Median commanded closure of each ``chunk``-step chunk (the agent replans every ``chunk``
    steps from the episode's first) in which the object was held at every step, in order: the
    chunks that hold it, not those that close on it or let go. The last chunk may be shorter."""
    closure, held = np.asarray(closure, np.float64), np.asarray(held, bool)
    if closure.shape != held.shape:
        raise ValueError(f"closure and held differ in length: {closure.shape} and {held.shape}")
    starts = range(0, len(closure), chunk)
    return np.array([np.median(closure[i:i + chunk]) for i in starts if held[i:i + chunk].all()])


def closure_summary(closure, held, chunk: int, grip=None) -> dict:
    """The commanded closure while the object was held: the first and last held chunk, the rise
    between them (0 for a policy that holds one closure, as the expert does), the spread (standard
    deviation) of the held chunks' medians (0 likewise; None for a single held chunk, which shows
    no switching either way), the largest closure of any held step, and
    ``let_go``: the closure commanded at the first step after the last held one (None if the object
    was held to the end), the release of a success or the opening that drops the object. With
    ``grip`` (each step's force on the weaker pad, N): ``grip_held`` at the last held step and
    ``grip_let_go`` at the let-go step (0 there: the fingers opened off the object; not 0: it
    slipped out under load). The last held step may already be the first of the chunk that lets go,
    so ``grip_held`` can show that chunk's transient rather than the hold's force."""
    medians = held_chunks(closure, held, chunk)
    closure, held = np.asarray(closure, np.float64), np.asarray(held, bool)
    last_held = len(held) - 1 - int(np.argmax(held[::-1])) if held.any() else None
    let_go_step = last_held + 1 if last_held is not None and last_held + 1 < len(closure) else None
    out = {"let_go": None if let_go_step is None else float(closure[let_go_step])}
    if grip is not None:
        grip = np.asarray(grip, np.float64)
        if grip.shape != closure.shape:
            raise ValueError(f"closure and grip differ in length: {closure.shape} and {grip.shape}")
        out["grip_held"] = None if last_held is None else float(grip[last_held])
        out["grip_let_go"] = None if let_go_step is None else float(grip[let_go_step])
    if len(medians) == 0:
        return {"held_chunks": 0, "first": None, "last": None, "rise": None, "spread": None, "max": None, **out}
    return {"held_chunks": int(len(medians)), "first": float(medians[0]), "last": float(medians[-1]),
            "rise": float(medians[-1] - medians[0]), "spread": float(medians.std()) if len(medians) > 1 else None,
            "max": float(closure[held].max()), **out}


def closure_readout(closures, held_widths, held_grips=None) -> dict:
    """How well the held jaw width tells the closure, across demos (one closure and one median held
    width each): their Pearson correlation, the least-squares slope (mm of width per unit of
    closure) and the range of held widths (mm). A width that does not move with the closure
    (rigid twin) leaves a policy's state blind to how hard it squeezes. With ``held_grips`` (the
    weaker pad's median held force, N), ``grip_corr``: how well the force, which touch sees,
    tells it."""
    c, w = np.asarray(closures, np.float64), np.asarray(held_widths, np.float64) * 1e3
    if c.shape != w.shape or len(c) < 3:
        raise ValueError(f"need one closure and one held width per demo, at least 3; got {c.shape} and {w.shape}")
    if np.ptp(c) == 0:
        raise ValueError("every demo has the same closure: nothing to read out")
    out = {"demos": int(len(c)), "corr": float(np.corrcoef(c, w)[0, 1]) if np.ptp(w) > 0 else 0.0,
           "slope_mm": float(np.polyfit(c, w, 1)[0]), "width_range_mm": [float(w.min()), float(w.max())],
           "closure_range": [float(c.min()), float(c.max())]}
    if held_grips is not None:
        g = np.asarray(held_grips, np.float64)
        if g.shape != c.shape:
            raise ValueError(f"need one held force per demo: {g.shape} for {c.shape} closures")
        out["grip_corr"] = float(np.corrcoef(c, g)[0, 1]) if np.ptp(g) > 0 else 0.0
    return out


# ManiSkill's articulation state row: root pose (7), root velocity (6), then qpos (n) and qvel (n).
ROOT_STATE_DIMS = 13
FINGER_JOINTS = 2  # the last two joints of the Panda's qpos: the jaw gap is their sum


def demo_closures(demos: DemoSet, task: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each accepted demo's closure (the expert's draw, the trajectory's ``closure`` attribute, which
    it commands for the whole hold), its held jaw width (median, m) and the weaker pad's held force
    (median, N), from the trajectory file alone. The width is the policy's (the finger joints' sum,
    :func:`~softvt_campaign.baselines.features.frame_features`), read from the robot's recorded
    state, one row per step after the reset's."""
    path = demos.trajectory(task)
    closures, widths, grips = [], [], []
    with open_h5(path) as traj:
        for name in traj:
            g = traj[name]
            held = np.asarray(g["evaluator/is_grasped"][()], bool)
            if not held.any():
                continue
            if "closure" not in g.attrs:
                raise ValueError(f"{path}/{name} has no 'closure' attribute (the expert's draw): it was recorded by "
                                 "another tool or version; record the demos again with `demos generate`")
            robots = g["env_states/articulations"]
            if len(robots) != 1:
                raise ValueError(f"{path}/{name}: expected the robot as the only articulation, found {sorted(robots)}")
            state = next(iter(robots.values()))[()]
            n = (state.shape[1] - ROOT_STATE_DIMS) // 2
            width = state[:, ROOT_STATE_DIMS + n - FINGER_JOINTS:ROOT_STATE_DIMS + n].sum(axis=1)
            closures.append(float(g.attrs["closure"]))
            # The state has one row more than the steps (the reset's): row t + 1 is after step t.
            widths.append(float(np.median(width[1:][held])))
            grips.append(float(np.median(np.asarray(g["evaluator/pad_force"][()]).min(axis=1)[held])))
    return np.array(closures), np.array(widths), np.array(grips)


class ClosureLog(Observer):
    """Each step's commanded closure (what the evaluator's trace does not keep)."""

    def __init__(self, gripper_column: int):
        self.gripper_column = gripper_column
        self.closure: list[float] = []

    def on_step(self, env, action, obs, info):
        self.closure.append(float(np.asarray(action)[self.gripper_column]))


def record_check(differing: dict, stored_stacks: list, current_stack: dict) -> dict:
    """The rerun episodes against their committed records, as ``evaluate --reproduce`` judges them:
    differing bits fail. ``differing``: seed -> the fields that differ
    (:func:`~mani_skill_softvt.evaluation.runner.record_differences`); ``stored_stacks``: the
    records' stacks (None for a record that predates them). What differs between the stacks
    explains differing bits (docs/evaluation.md: on another stack an episode keeps its outcome, not
    its bits), and ``records_outcome_differing`` says whether the outcomes held at least."""
    bad = {seed: d for seed, d in differing.items() if d}
    other = "unrecorded" if stored_stacks and not all(stored_stacks) else sorted(
        {d for st in stored_stacks for d in stack_differences(st, current_stack)})
    return {"records_checked": len(differing), "records_differing": bad, "records_stack_differences": other,
            "records_outcome_differing": sorted(seed for seed, d in bad.items() if set(d) & set(OUTCOME_FIELDS)),
            "records_failed": bool(bad)}


def _run(run, episodes: list[dict], queue) -> list[dict]:
    """A worker: each episode of ``run`` (a :class:`~mani_skill_softvt.evaluation.run.RunConfig`) as
    the evaluator runs it, with its closure log."""
    policy = run.policy.load()
    env = make_env(episodes[0]["suite"], episodes[0]["task_id"], obs_mode=run.obs_mode, control_mode=run.control_mode,
                   camera_size=run.camera_size)
    out = []
    try:
        for ep in episodes:
            # Whether the object was held and the pads' force: the evaluator's own trace, the weaker pad kept.
            log, trace = ClosureLog(GRIPPER), EvaluatorTrace()
            record = run_episode(env, policy, ep, policy_spec=run.policy.spec, policy_sha256=run.policy.sha256,
                                 observers=[log, trace])
            steps = trace.arrays()
            card = env.calibration_card
            out.append({"record": record, "chunk": policy.cfg.action_steps, "closure": log.closure,
                        "held": steps["is_grasped"].tolist(), "grip": steps["pad_force"].min(axis=1).tolist(),
                        "expert_closure": draw_closure(card, ep["seed"]), "g_min": card.g_min, "g_max": card.g_max})
            queue.put(ep["seed"])
    finally:
        env.close()
    return out


def summary_rows(episodes: list[dict], chunk: int) -> list[dict]:
    """Per episode: seed, ending, R_max, the expert's draw, the envelope's g_min and :func:`closure_summary`."""
    return [{"seed": e["record"]["seed"], "termination": e["record"]["termination"], "r_max": e["record"]["r_max"],
             "expert_closure": e["expert_closure"], "g_min": e["g_min"],
             **closure_summary(e["closure"], e["held"], chunk, e.get("grip"))}
            for e in episodes]


def plot(results: dict[str, list[dict]], suite: str, task: int, out: Path) -> None:
    """Closure (top) and R_t (bottom) over time, one column per policy, one colour per seed."""
    fig = Figure(figsize=(4.6 * len(results), 5.8))
    axes = fig.subplots(2, len(results), squeeze=False, sharex=True, sharey='row')
    for col, (name, episodes) in enumerate(results.items()):
        top, bottom = axes[0][col], axes[1][col]
        for i, e in enumerate(episodes):
            color = f"C{i % 10}"
            top.plot(np.arange(1, len(e["closure"]) + 1) / CONTROL_FREQ, e["closure"], color=color, lw=1,
                     label=str(e["record"]["seed"]))
            top.axhline(e["expert_closure"], color=color, ls="--", lw=0.8)
            bottom.plot(*rt_series(e["record"]), color=color, lw=1)
        for bound in ("g_min", "g_max"):  # the calibrated envelope the expert draws from
            top.axhline(episodes[0][bound], color="k", lw=0.8, ls=":")
        bottom.axhline(1.0, color="k", ls="--", lw=1)
        top.set_title(f"{name}, {suite} task {task}\ncommanded closure (dashed: the expert's draw; "
                      "dotted: g_min, g_max)", fontsize=8)
        bottom.set_title("R_t = D_t / tau_o", fontsize=8)
        bottom.set_xlabel("time (s)")
    axes[0][0].legend(fontsize=6, title="seed", title_fontsize=6, loc="lower right")
    fig.tight_layout()
    atomic_write(out, lambda p: fig.savefig(p, format="png", dpi=120))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("policies", nargs="+", help="trained policy files (a run's policy.pt or an exported .pt)")
    ap.add_argument("--suite", default="object_soft", choices=sorted(SUITES),
                    help="the suite the policies were trained on and run in (default object_soft)")
    ap.add_argument("--task", type=int, default=3, help="task id (default 3: on Object-Soft, the soft cube)")
    ap.add_argument("--episodes", type=int, default=6, help=f"the first N ID seeds of the task (1-{ID_EPISODES_PER_TASK})")
    ap.add_argument("--records", type=Path, default=Path("campaign-data/results"),
                    help="where the policies' ID records are, to check each episode against")
    ap.add_argument("--demos", type=Path, default=None,
                    help="the demos root (SOFTVT_DEMOS_DIR): also measure how the held jaw width reads out the "
                         "closure in the task's demos")
    ap.add_argument("--out", type=Path, default=Path("outputs/closure"))
    args = ap.parse_args(argv)
    if not 0 <= args.task < NUM_TASKS:
        ap.error(f"--task must be in [0, {NUM_TASKS - 1}], got {args.task}")
    if not 1 <= args.episodes <= ID_EPISODES_PER_TASK:
        ap.error(f"--episodes must be in [1, {ID_EPISODES_PER_TASK}] (the ID protocol's seeds), got {args.episodes}")
    runs = {}
    for spec in args.policies:
        if not spec.endswith(".pt") or not Path(spec).is_file():
            ap.error(f"{spec}: not a policy file; give the policy.pt of a trained baseline or an exported .pt")
        try:
            run = RunConfig.resolve(spec, suite=args.suite, tasks=[args.task], episodes_per_task=args.episodes)
        except (FileNotFoundError, ValueError) as e:
            ap.error(f"{spec}: {e}")
        if run.control_mode == "pd_ee_pose_binary":
            ap.error(f"{spec} commands a binary gripper (open or closed): it has no closure to follow")
        if policy_tag(spec) in runs:
            ap.error(f"two policies are named {policy_tag(spec)}; give each once, from differently named files")
        runs[policy_tag(spec)] = run
    readout = None
    if args.demos is not None:
        try:
            readout = closure_readout(*demo_closures(DemoSet(args.demos, args.suite), args.task))
        except (OSError, ValueError, KeyError) as e:  # a missing, truncated or foreign demo file
            ap.error(f"--demos {args.demos}: {e}")

    eps = next(iter(runs.values())).episodes()
    items = [(run, eps) for run in runs.values()]
    results = {}
    with tqdm(total=len(eps) * len(items), desc="closure", unit="episode") as bar:
        for kind, value in run_tasks(_run, items, workers=len(items)):
            if kind == "message":
                bar.update()
            else:
                tag = policy_tag(value[0]["record"]["policy"])
                results[tag] = value
    results = {tag: results[tag] for tag in runs}  # in the order given
    report = {"suite": args.suite, "task": args.task, "demo_readout": readout, "policies": {}}
    for tag, episodes_run in results.items():
        run, chunk = runs[tag], episodes_run[0]["chunk"]
        sha = run.policy.sha256
        stored = run_records(args.records / f"{run.stem}.jsonl", run)
        differing = {e["record"]["seed"]: record_differences(stored[episode_key(e["record"])], e["record"])
                     for e in episodes_run if episode_key(e["record"]) in stored}
        rows = summary_rows(episodes_run, chunk)
        stacks = [stored[episode_key(e["record"])]["receipt"].get("stack") for e in episodes_run
                  if episode_key(e["record"]) in stored]
        check = record_check(differing, stacks, software_stack())
        bad, other = check["records_differing"], check["records_stack_differences"]
        report["policies"][tag] = {"policy_sha256": sha, "chunk": chunk, "summary": rows, "episodes": episodes_run,
                                   **check}
        print(f"\n{tag}: median commanded closure of the first and last chunk of {chunk} steps that held the "
              "object, the spread of the held chunks, the largest held closure, the closure as the object "
              f"left the hand (g_min {rows[0]['g_min']:.2f}), the weaker pad's force (N) at the last held step "
              "and at that one")
        keys = ("first", "last", "spread", "max", "let_go", "grip_held", "grip_let_go")
        print(f"{'seed':>10} {'ending':>9} {'R_max':>6} {'expert':>7} " + " ".join(f"{k[:11]:>11}" for k in keys))
        for r in rows:
            cells = [f"{r[k]:>11.2f}" if r[k] is not None else f"{'-':>11}" for k in keys]
            print(f"{r['seed']:>10} {r['termination']:>9} {r['r_max']:>6.2f} {r['expert_closure']:>7.2f} {' '.join(cells)}")
        print(f"checked against {len(differing)} committed records of {args.records}: "
              + (f"{len(bad)} differ ({bad})" if bad else "the same, bit for bit"))
        if bad and other:
            made = ("before records named their stack" if other == "unrecorded"
                    else f"on another stack ({'; '.join(other)})")
            outcome = report["policies"][tag]["records_outcome_differing"]
            print(f"  the records were made {made}: bits are not expected to match there; the outcome "
                  f"({', '.join(OUTCOME_FIELDS)}) is the same in {len(differing) - len(outcome)} of {len(differing)}")
    if readout is not None:
        print(f"\ndemos of {args.suite} task {args.task}: {readout['demos']} closures in "
              f"[{readout['closure_range'][0]:.2f}, {readout['closure_range'][1]:.2f}] held the jaw at "
              f"{readout['width_range_mm'][0]:.2f}-{readout['width_range_mm'][1]:.2f} mm; width against closure: "
              f"r = {readout['corr']:+.2f}, {readout['slope_mm']:+.1f} mm per unit; the weaker pad's held force "
              f"against closure: r = {readout['grip_corr']:+.2f}")
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / f"closure_{args.suite}_task{args.task}"
    atomic_write_json(stem.with_suffix(".json"), report)
    plot(results, args.suite, args.task, stem.with_suffix(".png"))
    print(f"\n{stem.with_suffix('.json')}  {stem.with_suffix('.png')}")
    if any(p["records_failed"] for p in report["policies"].values()):
        raise SystemExit(1)  # not the episodes the records hold, bit for bit (as evaluate --reproduce)
    return report


if __name__ == "__main__":
    main()
