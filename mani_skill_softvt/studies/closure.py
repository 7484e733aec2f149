"""How trained policies close the gripper over an episode, beside the expert's closure for the same seed.

    python -m mani_skill_softvt.studies.closure baselines/policies/vo-c-cpu.pt \
        baselines/policies/vt-c-cpu.pt --task 3 --episodes 6 --out baselines/results

The scripted expert draws one closure per episode, uniform in the object's calibrated envelope
[g_min, g_max], and commands it at once for the whole hold (``expert.pick_place``). A learned
policy commands its closure afresh in every chunk. This runs each policy (one worker each, one
BLAS thread, as evaluation workers do) on the first ``--episodes`` ID seeds of a task through the
evaluator's own episode (:func:`~mani_skill_softvt.evaluation.runner.run_episode`), and keeps
every step's commanded closure (the action's gripper column) and whether the object was held.
Each episode's record is checked against the policy's committed ID records in ``--records``
(``evaluate``'s files), which it must match bit for bit.

It writes ``closure_task<T>.json`` (the closures, R_t, the summaries below, each policy's SHA-256)
and ``closure_task<T>.png`` (closure and R_t over time, one column per policy; the expert's draw
for each seed dashed), and prints per episode the closure of the first and last chunks that held
the object.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from tqdm import tqdm

from ..baselines.agent import GRIPPER
from ..data.seeds import ID_EPISODES_PER_TASK
from ..evaluation.protocols import episode_key
from ..evaluation.report import rt_series
from ..evaluation.run import RunConfig, policy_tag
from ..evaluation.runner import record_differences, run_episode, run_records
from ..evaluation.wrapper import make_env
from ..expert.pick_place import draw_closure
from ..fileio import atomic_write, atomic_write_json
from ..observations import info_bool
from ..parallel import run_tasks
from ..physics.constants import CONTROL_FREQ
from ..rollout import Observer
from ..tasks.suites import NUM_TASKS


def held_chunks(closure, held, chunk: int) -> np.ndarray:
    """Median commanded closure of each ``chunk``-step chunk (the agent replans every ``chunk``
    steps from the episode's first) in which the object was held at every step, in order: the
    chunks that hold it, not those that close on it or let go. The last chunk may be shorter."""
    closure, held = np.asarray(closure, np.float64), np.asarray(held, bool)
    if closure.shape != held.shape:
        raise ValueError(f"closure and held differ in length: {closure.shape} and {held.shape}")
    starts = range(0, len(closure), chunk)
    return np.array([np.median(closure[i:i + chunk]) for i in starts if held[i:i + chunk].all()])


def closure_summary(closure, held, chunk: int) -> dict:
    """The commanded closure while the object was held: the first and last held chunk, the rise
    between them (0 for a policy that holds one closure, as the expert does) and the largest
    closure of any held step."""
    medians = held_chunks(closure, held, chunk)
    if len(medians) == 0:
        return {"held_chunks": 0, "first": None, "last": None, "rise": None, "max": None}
    held_closure = np.asarray(closure, np.float64)[np.asarray(held, bool)]
    return {"held_chunks": int(len(medians)), "first": float(medians[0]), "last": float(medians[-1]),
            "rise": float(medians[-1] - medians[0]), "max": float(held_closure.max())}


class ClosureLog(Observer):
    """Each step's commanded closure and whether the env said the object was held."""

    def __init__(self, gripper_column: int):
        self.gripper_column = gripper_column
        self.closure: list[float] = []
        self.held: list[bool] = []

    def on_step(self, env, action, obs, info):
        self.closure.append(float(np.asarray(action)[self.gripper_column]))
        self.held.append(info_bool(info, "is_grasped"))


def _run(run, episodes: list[dict], queue) -> list[dict]:
    """A worker: each episode of ``run`` (a :class:`~mani_skill_softvt.evaluation.run.RunConfig`) as
    the evaluator runs it, with its closure log."""
    policy = run.policy.load()
    env = make_env(episodes[0]["suite"], episodes[0]["task_id"], obs_mode=run.obs_mode, control_mode=run.control_mode,
                   camera_size=run.camera_size)
    out = []
    try:
        for ep in episodes:
            log = ClosureLog(GRIPPER)
            record = run_episode(env, policy, ep, policy_spec=run.policy.spec, policy_sha256=run.policy.sha256,
                                 observers=[log])
            card = env.calibration_card
            out.append({"record": record, "chunk": policy.cfg.action_steps, "closure": log.closure, "held": log.held,
                        "expert_closure": draw_closure(card, ep["seed"]), "g_min": card.g_min, "g_max": card.g_max})
            queue.put(ep["seed"])
    finally:
        env.close()
    return out


def summary_rows(episodes: list[dict], chunk: int) -> list[dict]:
    """Per episode: seed, ending, R_max, the expert's draw and :func:`closure_summary`."""
    return [{"seed": e["record"]["seed"], "termination": e["record"]["termination"], "r_max": e["record"]["r_max"],
             "expert_closure": e["expert_closure"], **closure_summary(e["closure"], e["held"], chunk)}
            for e in episodes]


def plot(results: dict[str, list[dict]], task: int, out: Path) -> None:
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
        top.axhline(episodes[0]["g_max"], color="k", lw=0.8, ls=":")
        bottom.axhline(1.0, color="k", ls="--", lw=1)
        top.set_title(f"{name}, object_soft task {task}\ncommanded closure (dashed: the expert's draw; "
                      "dotted: g_max)", fontsize=8)
        bottom.set_title("R_t = D_t / tau_o", fontsize=8)
        bottom.set_xlabel("time (s)")
    axes[0][0].legend(fontsize=6, title="seed", title_fontsize=6, loc="lower right")
    fig.tight_layout()
    atomic_write(out, lambda p: fig.savefig(p, format="png", dpi=120))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("policies", nargs="+", help="trained policy files (a run's policy.pt or an exported .pt)")
    ap.add_argument("--task", type=int, default=3, help="Object-Soft task (default 3, the soft cube)")
    ap.add_argument("--episodes", type=int, default=6, help=f"the first N ID seeds of the task (1-{ID_EPISODES_PER_TASK})")
    ap.add_argument("--records", type=Path, default=Path("baselines/results"),
                    help="where the policies' ID records are, to check each episode against")
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
            run = RunConfig.resolve(spec, suite="object_soft", tasks=[args.task], episodes_per_task=args.episodes)
        except (FileNotFoundError, ValueError) as e:
            ap.error(f"{spec}: {e}")
        if run.control_mode == "pd_ee_pose_binary":
            ap.error(f"{spec} commands a binary gripper (open or closed): it has no closure to follow")
        if policy_tag(spec) in runs:
            ap.error(f"two policies are named {policy_tag(spec)}; give each once, from differently named files")
        runs[policy_tag(spec)] = run

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
    report = {"task": args.task, "policies": {}}
    for tag, episodes_run in results.items():
        run, chunk = runs[tag], episodes_run[0]["chunk"]
        sha = run.policy.sha256
        stored = run_records(args.records / f"{run.stem}.jsonl", run)
        differing = {e["record"]["seed"]: record_differences(stored[episode_key(e["record"])], e["record"])
                     for e in episodes_run if episode_key(e["record"]) in stored}
        rows = summary_rows(episodes_run, chunk)
        report["policies"][tag] = {"policy_sha256": sha, "chunk": chunk, "summary": rows, "episodes": episodes_run,
                                   "records_checked": len(differing),
                                   "records_differing": {s: d for s, d in differing.items() if d}}
        print(f"\n{tag}: median commanded closure of the first and last chunk of {chunk} steps that held the "
              "object, the largest held closure")
        print(f"{'seed':>10} {'ending':>9} {'R_max':>6} {'expert':>7} {'first':>6} {'last':>6} {'max':>6}")
        for r in rows:
            cells = [f"{r[k]:>6.2f}" if r[k] is not None else f"{'-':>6}" for k in ("first", "last", "max")]
            print(f"{r['seed']:>10} {r['termination']:>9} {r['r_max']:>6.2f} {r['expert_closure']:>7.2f} {' '.join(cells)}")
        bad = report["policies"][tag]["records_differing"]
        print(f"checked against {len(differing)} committed records of {args.records}: "
              + (f"{len(bad)} differ ({bad})" if bad else "the same, bit for bit"))
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / f"closure_task{args.task}"
    atomic_write_json(stem.with_suffix(".json"), report)
    plot(results, args.task, stem.with_suffix(".png"))
    print(f"\n{stem.with_suffix('.json')}  {stem.with_suffix('.png')}")
    if any(p["records_differing"] for p in report["policies"].values()):
        raise SystemExit(1)
    return report


if __name__ == "__main__":
    main()
