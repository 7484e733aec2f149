"""How trained policies close the gripper over an episode, beside the expert's closure for the same seed.

    python -m mani_skill_softvt.baselines.closure baselines/policies/vo-c-cpu.pt \
        baselines/policies/vt-c-cpu.pt --task 3 --episodes 6 --out baselines/results

The scripted expert draws one closure per episode, uniform in the object's calibrated envelope
[g_min, g_max], and commands it at once for the whole hold (``expert.pick_place``). A learned
policy commands its closure afresh in every chunk. This runs each policy on the first
``--episodes`` ID seeds of a task as ``evaluate`` does (the same env, rollout and modes, cameras
only where read, so R_max equals the committed record's) and keeps every step's commanded
closure (the action's last entry) and R_t. It writes ``closure_task<T>.json`` and
``closure_task<T>.png`` (closure and R_t over time, one column per policy; the expert's draw for
each seed dashed) and prints per episode the closure of the first and last held chunks.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..fileio import atomic_write, atomic_write_json


def held_chunks(closure, chunk: int, closed_at: float) -> np.ndarray:
    """Median commanded closure of each ``chunk``-step chunk closed at least to ``closed_at`` in
    every step, in order: the chunks that hold the object, not those that close or release it."""
    closure = np.asarray(closure, np.float64)
    chunks = [closure[i:i + chunk] for i in range(0, len(closure), chunk)]
    return np.array([np.median(c) for c in chunks if c.min() >= closed_at])


def closure_summary(closure, chunk: int, closed_at: float) -> dict:
    """The commanded closure while holding: its first and last held chunk, its largest step, and the
    rise between them (a policy that holds one closure, as the expert does, rises by 0)."""
    held = held_chunks(closure, chunk, closed_at)
    if len(held) == 0:
        return {"held_chunks": 0, "first": None, "last": None, "rise": None, "max": None}
    return {"held_chunks": int(len(held)), "first": float(held[0]), "last": float(held[-1]),
            "rise": float(held[-1] - held[0]), "max": float(np.max(closure))}


def run(policy_spec: str, task: int, seeds: list[int], progress=None) -> list[dict]:
    """Each seed's episode of the policy, as ``evaluate`` runs it, with its closure and R_t per step."""
    from ..evaluation.policies import load_policy, policy_camera_size
    from ..evaluation.report import rt_series
    from ..evaluation.wrapper import make_env
    from ..expert.pick_place import draw_closure
    from ..rollout import Observer, rollout
    from .agent import required_modes

    obs_mode, control_mode = required_modes(Path(policy_spec))
    policy = load_policy(policy_spec)
    env = make_env("object_soft", task, obs_mode=obs_mode, control_mode=control_mode,
                   camera_size=policy_camera_size(policy_spec))
    episodes = []
    try:
        for seed in seeds:
            closure = []

            class Closure(Observer):
                def on_step(self, env, action, obs, info):
                    closure.append(float(np.asarray(action)[-1]))

            ep = rollout(env, policy, seed, observers=[Closure()], until="episode", skip_unread_cameras=True)
            card = env.calibration_card
            _, rt = rt_series({"deformation_trace": env.deformation_trace, "tau_o": env.tau_o})
            episodes.append({"seed": seed, "termination": ep.termination, "r_max": float(env.r_max),
                             "expert_closure": draw_closure(card, seed), "g_min": card.g_min, "g_max": card.g_max,
                             "closure": closure, "r_t": [float(v) for v in rt]})
            if progress is not None:
                progress()
    finally:
        env.close()
    return episodes


def plot(results: dict[str, list[dict]], task: int, out: Path) -> None:
    """Closure (top) and R_t (bottom) over time, one column per policy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..physics.constants import CONTROL_FREQ

    fig, axes = plt.subplots(2, len(results), figsize=(4.6 * len(results), 5.6), squeeze=False, sharex=True,
                             sharey="row")
    for col, (name, episodes) in enumerate(results.items()):
        top, bottom = axes[0][col], axes[1][col]
        for i, e in enumerate(episodes):
            color = f"C{i % 10}"
            top.plot(np.arange(1, len(e["closure"]) + 1) / CONTROL_FREQ, e["closure"], color=color, lw=1)
            top.axhline(e["expert_closure"], color=color, ls="--", lw=0.8)
            bottom.plot(np.arange(len(e["r_t"])) / CONTROL_FREQ, e["r_t"], color=color, lw=1)
        g_max = episodes[0]["g_max"] if episodes else None
        if g_max is not None:
            top.axhline(g_max, color="k", lw=0.8, ls=":")
        bottom.axhline(1.0, color="k", ls="--", lw=1)
        top.set_title(f"{name}, object_soft task {task}\ncommanded closure (dashed: the expert's draw; "
                      "dotted: g_max)", fontsize=8)
        bottom.set_title("R_t = D_t / tau_o", fontsize=8)
        bottom.set_xlabel("time (s)")
    fig.tight_layout()
    atomic_write(out, lambda p: fig.savefig(p, format="png", dpi=120))
    plt.close(fig)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("policies", nargs="+", help="trained policy files (policy.pt)")
    ap.add_argument("--task", type=int, default=3, help="Object-Soft task (default 3, the soft cube)")
    ap.add_argument("--episodes", type=int, default=6, help="the first N ID seeds of the task")
    ap.add_argument("--out", type=Path, default=Path("baselines/results"))
    args = ap.parse_args(argv)
    for spec in args.policies:
        if not spec.endswith(".pt") or not Path(spec).is_file():
            ap.error(f"{spec}: not a policy file; give the policy.pt of a trained baseline")
    from tqdm import tqdm

    from ..data.seeds import id_seed
    from .agent import read_policy_file

    seeds = [id_seed(args.task, i) for i in range(args.episodes)]
    results = {}
    with tqdm(total=len(seeds) * len(args.policies), desc="closure", unit="episode") as bar:
        for spec in args.policies:
            results[Path(spec).stem] = run(spec, args.task, seeds, progress=bar.update)
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / f"closure_task{args.task}"
    atomic_write_json(stem.with_suffix(".json"), {"task": args.task, "policies": results})
    plot(results, args.task, stem.with_suffix(".png"))
    for name, episodes in results.items():
        cfg, _ = read_policy_file(Path(next(p for p in args.policies if Path(p).stem == name)))
        print(f"\n{name}: median closure of the first and last chunk of {cfg.action_steps} steps that hold "
              "(every step closed to at least g_min / 2), and the largest step")
        print(f"{'seed':>10} {'ending':>9} {'R_max':>6} {'expert':>7} {'first':>6} {'last':>6} {'max':>6}")
        for e in episodes:
            s = closure_summary(e["closure"], cfg.action_steps, e["g_min"] / 2)
            cells = [f"{s[k]:>6.2f}" if s[k] is not None else f"{'-':>6}" for k in ("first", "last", "max")]
            print(f"{e['seed']:>10} {e['termination']:>9} {e['r_max']:>6.2f} {e['expert_closure']:>7.2f} {' '.join(cells)}")
    print(f"\n{stem.with_suffix('.json')}  {stem.with_suffix('.png')}")
    return results


if __name__ == "__main__":
    main()
