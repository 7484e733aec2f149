"""Expert demonstrations in ManiSkill's trajectory format (.h5 + .json), with quality control.

Each episode is recorded once (physics runs once) into its own small HDF5 file, written
atomically, so generation resumes per episode; ``merge`` then packs the accepted episodes into
one ManiSkill trajectory file. Per episode ``traj_<i>`` holds ManiSkill's ``actions``,
``terminated``, ``truncated``, ``success``, ``fail`` and ``env_states`` (including the FEM state,
so ``set_state_dict`` replays it exactly), plus ``actions_binary`` (the same actions in the binary
gripper encoding) and an ``evaluator/`` group (FEM nodes, object centroids, D_t, R_t, grasp,
contact and drop events) that never enters any observation.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import h5py
import numpy as np

from ..expert.pick_place import DEFAULT_PLANNER
from ..fileio import atomic_write, atomic_write_json
from ..tactile.constants import MODEL_VERSION as TACTILE_MODEL_VERSION

_CLOSURE_DESC = "closure drawn from the calibrated envelope [g_min, g_max]"
SOURCE_DESCS = {
    "mplib": ("mani_skill_softvt scripted expert: mplib joint-space motion planning (screw paths, RRTConnect opt-in, "
              "TOPP-RA at 20 Hz) around the table, target prop and other instance, replayed as absolute "
              f"end-effector poses (forward kinematics), {_CLOSURE_DESC}"),
    "cartesian": ("mani_skill_softvt scripted expert: Cartesian waypoints through the absolute end-effector pose "
                  f"controller, {_CLOSURE_DESC}"),
}
SOURCE_DESC = SOURCE_DESCS[DEFAULT_PLANNER]
REGENERATE = "delete it and re-run the command that wrote it ('demos generate' resumes, 'demos render' rewrites)"


class CorruptDataError(OSError):
    """A demonstration file that cannot be read (truncated by a killed writer or a full disk, or damaged)."""


@contextmanager
def open_h5(path: Path) -> Iterator[h5py.File]:
    """``h5py.File(path, "r")`` whose failure names the file: missing, truncated or not HDF5.

    HDF5 records its end of file in the superblock, so a truncated file fails here, at open.
    A damaged dataset fails only when read: :func:`check_h5` reads them all.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist; generate (and render) the demos first")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise CorruptDataError(f"{path} is not a readable HDF5 file ({e}): it is truncated or corrupt; "
                               f"{REGENERATE}") from None
    with f:
        yield f


def check_h5(path: Path, read: bool = True) -> str | None:
    """Why ``path`` cannot be opened, or with ``read`` read in full (every dataset); None if it can."""
    try:
        with open_h5(path) as f:
            if not read:
                return None
            try:
                f.visititems(lambda _, v: v[()] if isinstance(v, h5py.Dataset) else None)
            except OSError as e:  # h5py's read errors name neither the file nor what to do
                return f"{path}: reading failed ({e}): the file is corrupt; {REGENERATE}"
    except (CorruptDataError, FileNotFoundError) as e:
        return str(e)
    return None


def source_desc(planners) -> str:
    """ManiSkill ``source_desc`` of a trajectory file whose episodes came from ``planners``."""
    planners = sorted(set(planners))
    if len(planners) == 1:
        return SOURCE_DESCS[planners[0]]
    return "mani_skill_softvt scripted expert, mixed planners: " + "; ".join(
        f"{p}: {SOURCE_DESCS[p]}" for p in planners)


def flatten_batch(tree: dict, prefix: str = "") -> dict[str, np.ndarray]:
    """Env state or observation (nested dicts, batch of one) as ``{"a/b": array}`` without the batch
    axis; strings (the instruction) are left out: a trajectory stores its instruction once. The
    rendered files' keys, and what a baseline policy reads live (``baselines.features``)."""
    out = {}
    for k, v in tree.items():
        key = f"{prefix}/{k}" if prefix else k
        if isinstance(v, dict):
            out.update(flatten_batch(v, key))
        elif not isinstance(v, str):
            out[key] = np.asarray(v.cpu().numpy() if hasattr(v, "cpu") else v)[0]
    return out


def record_episode(env, seed: int, closure: float, planner: str = DEFAULT_PLANNER) -> dict:
    """Run the expert once on a DSR-wrapped suite env; return every stream as numpy arrays."""
    from ..expert.pick_place import expert_actions, plan_pick_place

    obs, info = env.reset(seed=seed)
    u = env.unwrapped
    name = u.target_instance
    states = [flatten_batch(u.get_state_dict())]
    ev = {"nodes": [u.soft_nodes(name).astype(np.float32)],
          "centroids": [np.stack([u.soft_nodes(n).mean(0) for n in u.object_names])],
          "deformation": [env.deformation_trace[-1]], "deformation_ratio": [info["deformation_ratio"]]}
    acts, terms, truncs, succ, fail, grasp, drop, force = [], [], [], [], [], [], [], []
    plan = plan_pick_place(env, closure, planner)  # plan.planner: the planner actually used (mplib falls back)
    for _, action in expert_actions(env, plan):
        obs, _, terminated, truncated, info = env.step(action)
        acts.append(action)
        terms.append(bool(terminated[0]))
        truncs.append(bool(truncated[0]))
        succ.append(bool(info["success"][0]))
        fail.append(bool(info["fail"][0]))
        grasp.append(bool(info["is_grasped"][0]))
        drop.append(bool(info["dropped"][0]))
        pads = u.pad_forces()
        force.append([pads["left"], pads["right"]])
        states.append(flatten_batch(u.get_state_dict()))
        ev["nodes"].append(u.soft_nodes(name).astype(np.float32))
        ev["centroids"].append(np.stack([u.soft_nodes(n).mean(0) for n in u.object_names]))
        ev["deformation"].append(env.deformation_trace[-1])
        ev["deformation_ratio"].append(info["deformation_ratio"])
        if terms[-1] or truncs[-1]:
            break
    actions = np.asarray(acts, np.float32)
    binary = actions.copy()
    binary[:, 6] = (actions[:, 6] > 0.0).astype(np.float32)  # any commanded closure = "close"
    return {
        "seed": int(seed), "closure": float(closure), "instruction": u.instruction, "target_instance": name,
        "planner": plan.planner,
        "actions": actions, "actions_binary": binary, "terminated": np.asarray(terms), "truncated": np.asarray(truncs),
        "success": np.asarray(succ), "fail": np.asarray(fail),
        "env_states": {k: np.stack([s[k] for s in states]) for k in states[0]},
        "evaluator": {"nodes": np.stack(ev["nodes"]), "object_centroids": np.stack(ev["centroids"]),
                      "deformation": np.asarray(ev["deformation"]), "deformation_ratio": np.asarray(ev["deformation_ratio"]),
                      "is_grasped": np.asarray(grasp), "dropped": np.asarray(drop), "pad_force": np.asarray(force),
                      "tau_o": np.float64(env.tau_o)},
    }


def screen(ep: dict) -> list[str]:
    """Integrity problems of an episode (empty list: accepted)."""
    problems = []
    t = len(ep["actions"])
    if t == 0:
        return ["no steps"]
    for k in ("terminated", "truncated", "success", "fail"):
        if len(ep[k]) != t:
            problems.append(f"{k} has {len(ep[k])} steps, actions {t}")
    for k, v in ep["env_states"].items():
        if len(v) != t + 1:
            problems.append(f"env_states/{k} has {len(v)} entries, expected {t + 1}")
    for k in ("nodes", "deformation", "deformation_ratio"):
        if len(ep["evaluator"][k]) != t + 1:
            problems.append(f"evaluator/{k} has {len(ep['evaluator'][k])} entries, expected {t + 1}")
    arrays = [ep["actions"], *ep["env_states"].values(), ep["evaluator"]["nodes"], ep["evaluator"]["deformation"]]
    if any(not np.all(np.isfinite(a)) for a in arrays if np.issubdtype(np.asarray(a).dtype, np.floating)):
        problems.append("NaN or inf in the recorded streams")
    if not ep["success"][-1]:
        problems.append("not successful at the last step")
    if ep["evaluator"]["dropped"].any():
        problems.append("object dropped")
    r_max = float(np.max(ep["evaluator"]["deformation_ratio"]))
    if r_max > 1.0:
        problems.append(f"R_max {r_max:.3f} > 1")
    return problems


def write_episode(ep: dict, path: Path) -> None:
    """One episode's HDF5 (atomically)."""
    def write(tmp: Path):
        with h5py.File(tmp, "w") as f:
            _write_traj(f.create_group("traj"), ep)
    atomic_write(path, write)


def _dataset(group, key: str, data) -> None:
    data = np.asarray(data)
    # Large per-step arrays (FEM nodes, states) compress well; gzip is lossless and deterministic.
    opts = {"compression": "gzip", "compression_opts": 4} if data.size > 4096 else {}
    group.create_dataset(key, data=data, **opts)


def _write_traj(g, ep: dict) -> None:
    for k in ("actions", "actions_binary", "terminated", "truncated", "success", "fail"):
        _dataset(g, k, ep[k])
    s = g.create_group("env_states")
    for k, v in ep["env_states"].items():
        _dataset(s, k, v)
    e = g.create_group("evaluator")
    for k, v in ep["evaluator"].items():
        _dataset(e, k, v)
    for k in ("seed", "closure", "instruction", "target_instance"):
        g.attrs[k] = ep[k]
    g.attrs["planner"] = ep["planner"]


def read_episode(path: Path) -> dict:
    with open_h5(path) as f:
        g = f["traj"]
        ep = {k: g[k][()] for k in ("actions", "actions_binary", "terminated", "truncated", "success", "fail")}
        ep["env_states"] = {}
        g["env_states"].visititems(lambda k, v: ep["env_states"].__setitem__(k, v[()]) if isinstance(v, h5py.Dataset) else None)
        ep["evaluator"] = {k: g["evaluator"][k][()] for k in g["evaluator"]}
        ep.update({k: (v.decode() if isinstance(v, bytes) else v) for k, v in g.attrs.items()})
    return ep


def merge(episode_files: list[Path], out_h5: Path, env_id: str, env_kwargs: dict, control_mode: str,
          max_episode_steps: int) -> dict:
    """Pack episodes into ``out_h5`` + its ManiSkill ``.json`` (source_type motionplanning)."""
    meta = {"env_info": {"env_id": env_id, "env_kwargs": env_kwargs, "max_episode_steps": max_episode_steps},
            "source_type": "motionplanning", "source_desc": SOURCE_DESC, "episodes": []}
    planners = []

    def write(tmp: Path):
        with h5py.File(tmp, "w") as f:
            for i, path in enumerate(episode_files):
                ep = read_episode(path)
                planners.append(ep["planner"])
                _write_traj(f.create_group(f"traj_{i}"), ep)
                meta["episodes"].append({
                    "episode_id": i, "episode_seed": int(ep["seed"]), "reset_kwargs": {"seed": int(ep["seed"])},
                    "control_mode": control_mode, "elapsed_steps": int(len(ep["actions"])),
                    "success": bool(ep["success"][-1]), "instruction": ep["instruction"], "closure": float(ep["closure"]),
                    "r_max": float(np.max(ep["evaluator"]["deformation_ratio"])), "planner": planners[-1],
                })
            meta["source_desc"] = source_desc(planners) if planners else SOURCE_DESC
    atomic_write(out_h5, write)
    atomic_write_json(out_h5.with_suffix(".json"), meta)
    return meta


def episode_json_line(ep: dict, problems: list[str]) -> str:
    return json.dumps({"seed": ep["seed"], "planner": ep["planner"], "accepted": not problems,
                       "problems": problems,
                       "steps": int(len(ep["actions"])), "r_max": float(np.max(ep["evaluator"]["deformation_ratio"]))})


def _state_dict_at(env_states: dict, t: int) -> dict:
    """Nested env state (ManiSkill's get_state_dict layout, batch of one) at step ``t``."""
    import torch

    state: dict = {}
    for key, v in env_states.items():
        node = state
        parts = key.split("/")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = torch.from_numpy(np.asarray(v[t])[None])
    return state


def tactile_model_of(episode_group) -> int:
    """The tactile model version an episode's observations were rendered with (1 if unrecorded:
    renderings from before the version was kept)."""
    return int(episode_group.attrs.get("tactile_model", 1))


def render_observations(trajectory_h5: Path, out_h5: Path, suite: str, task_id: int, obs_mode: str) -> int:
    """Re-render stored episodes into ``obs_mode`` observations on the same 20 Hz timeline.

    Every recorded env state (reset + one per step) is restored and observed in order, so the
    cameras, the tactile images (whose shear tracking follows the episode) and the actions share
    one timeline with no resampling. Observations go to ``traj_<i>/obs/...`` of ``out_h5``.
    """
    from ..evaluation.wrapper import make_env

    problem = check_h5(trajectory_h5)  # small (states only): read it all before building the env
    if problem:
        raise CorruptDataError(problem)
    env = make_env(suite, task_id, dsr=False, obs_mode=obs_mode)
    u = env.unwrapped
    n = 0

    def write(tmp: Path):
        nonlocal n
        with h5py.File(trajectory_h5, "r") as src, h5py.File(tmp, "w") as dst:
            for name in sorted(src.keys(), key=lambda k: int(k.split("_")[1])):
                g = src[name]
                states = {}
                g["env_states"].visititems(lambda k, v: states.__setitem__(k, v[()]) if isinstance(v, h5py.Dataset) else None)
                env.reset(seed=int(g.attrs["seed"]))
                frames = []
                steps = {len(v) for v in states.values()}  # one state per step in every group
                if len(steps) != 1:
                    raise CorruptDataError(f"{trajectory_h5}:{name}: env_states groups differ in length {sorted(steps)}")
                for t in range(steps.pop()):
                    u.set_state_dict(_state_dict_at(states, t))
                    frames.append(flatten_batch(u.get_obs()))
                out = dst.create_group(name)
                out.attrs["instruction"] = g.attrs["instruction"]
                if "tactile" in obs_mode:
                    out.attrs["tactile_model"] = TACTILE_MODEL_VERSION
                for k in frames[0]:
                    _dataset(out, f"obs/{k}", np.stack([f[k] for f in frames]))
                n += 1
    try:
        atomic_write(out_h5, write)
    finally:
        env.close()
    return n
