"""Expert demonstrations in ManiSkill's trajectory format (.h5 + .json): reading, screening, rendering.

Episodes are recorded by ManiSkill's ``RecordEpisode`` with SoftVT's evaluator stream beside the
observations (:class:`~mani_skill_softvt.data.record.SoftVTRecordEpisode`), one small file per
episode (``demos generate`` resumes per episode), then merged per task with ManiSkill's
``merge_trajectories``. Per episode ``traj_<i>`` holds ManiSkill's ``actions``, ``terminated``,
``truncated``, ``success``, ``fail``, ``env_states`` (including the FEM state, so
``set_state_dict`` replays it exactly), ``actions_binary`` (the same actions in the binary
gripper encoding), an ``evaluator/`` group (FEM nodes, object centroids, D_t, R_t, collapsed
tets, grasp, contact and drop events) that never enters any observation, and the episode's ``seed``,
``closure``, ``instruction``, ``target_instance`` and ``planner`` as attributes (also in the json).
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import h5py
import numpy as np
import torch

from ..fileio import atomic_write, atomic_write_json, read_json
from ..contracts.observations import nest
from ..provenance import RENDER_VERSION  # what a rendering holds; its history is there
from ..contracts.actions import GRIPPER_ACTION_VERSION, GRIPPER_ACTION_VERSIONS, UPGRADE_COMMAND, gripper_action, normalized_gripper
from ..tasks.objects import TWIN_CONTACT_STATE
from ..tasks.suites import parse_env_id, recorded_env_id

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
    collapsed = np.asarray(ep["evaluator"].get("collapsed_tets", 0))  # not in demos recorded before it was kept
    if collapsed.any():
        problems.append(f"a tet collapsed ({int(collapsed.max())} at most) in {int((collapsed > 0).sum())} states")
    return problems


# Per-step datasets of a ManiSkill trajectory (and the package's binary-gripper actions).
MANISKILL_STEP_KEYS = ("actions", "actions_binary", "terminated", "truncated", "success", "fail")


def _dataset(group, key: str, data) -> None:
    data = np.asarray(data)
    # Large per-step arrays (FEM nodes, states) compress well; gzip is lossless and deterministic.
    opts = {"compression": "gzip", "compression_opts": 4} if data.size > 4096 else {}
    group.create_dataset(key, data=data, **opts)


def read_episode(path: Path, traj: str = "traj_0") -> dict:
    """One recorded episode (``traj`` of a trajectory file) as numpy arrays and its attributes."""
    with open_h5(path) as f:
        if traj not in f:
            raise CorruptDataError(f"{path} holds no episode '{traj}' (it has {sorted(f.keys())}): it was written "
                                   f"by an older version or another tool; {REGENERATE}")
        g = f[traj]
        ep = {k: g[k][()] for k in MANISKILL_STEP_KEYS if k in g}  # binary-mode demos have no actions_binary
        ep["env_states"] = {}
        g["env_states"].visititems(lambda k, v: ep["env_states"].__setitem__(k, v[()]) if isinstance(v, h5py.Dataset) else None)
        ep["evaluator"] = {k: g["evaluator"][k][()] for k in g["evaluator"]}
        ep.update({k: _attr_value(v) for k, v in g.attrs.items()})
    return ep


def _attr_value(v):
    """An HDF5 attribute as a plain Python value (text decoded, numpy scalars unwrapped)."""
    if isinstance(v, bytes):
        return v.decode()
    return v.item() if isinstance(v, np.generic) else v


def episode_json_line(ep: dict, problems: list[str]) -> str:
    return json.dumps({"seed": ep["seed"], "planner": ep["planner"], "accepted": not problems,
                       "problems": problems,
                       "steps": int(len(ep["actions"])), "r_max": float(np.max(ep["evaluator"]["deformation_ratio"]))})


def state_dict_at(env_states: dict, t: int) -> dict:
    """Nested env state (ManiSkill's get_state_dict layout, batch of one) at step ``t``."""
    return nest({key: torch.from_numpy(np.asarray(v[t])[None]) for key, v in env_states.items()})


def tactile_model_of(episode_group) -> int:
    """The tactile model version an episode's observations were rendered with (1 if unrecorded:
    renderings from before the version was kept)."""
    return int(episode_group.attrs.get("tactile_model", 1))


def episode_digest(group) -> str:
    """SHA-256 of a stored episode's env states and actions: everything its rendering depends on
    (a rendered episode keeps the digest of its source, so an unchanged episode is never rendered twice)."""
    arrays = {"actions": group["actions"]}
    group["env_states"].visititems(lambda k, v: arrays.__setitem__(f"env_states/{k}", v)
                                   if isinstance(v, h5py.Dataset) else None)
    h = hashlib.sha256()
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key][()])
        h.update(f"{key}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def holds_twin_contact(episode_group) -> bool:
    """Whether a rigid-twin episode's env states hold the contact wrenches its touch is rendered
    from. Recordings from before they were kept render the pinched twin on a blank gel."""
    return f"env_states/{TWIN_CONTACT_STATE}" in episode_group


def rendering_current(rendered_group, digest: str, needed: tuple[str, ...] = (), tactile_model: int | None = None) -> bool:
    """Whether a rendered episode is the rendering of the episode with ``digest`` as this version
    renders it: its source's digest, :data:`RENDER_VERSION`, the ``needed`` observation keys
    (older renderings lack the depth map) and, if given, frames of that ``tactile_model``."""
    return (rendered_group.attrs.get("states_sha256") == digest
            and int(rendered_group.attrs.get("render_version", 1)) == RENDER_VERSION and "obs" in rendered_group
            and all(n in rendered_group["obs"] for n in needed)
            and (tactile_model is None or tactile_model_of(rendered_group) == tactile_model))


RENDER_PART_EPISODES = 10  # episodes per part file: what a rendering killed mid-task can lose


def rendering_parts_dir(out_h5: Path) -> Path:
    """Where a rendering under way keeps its finished parts (``<name>.parts/`` beside ``out_h5``:
    not an ``.h5``, so no trajectory glob of the demo store picks it up)."""
    out_h5 = Path(out_h5)
    return out_h5.with_name(f"{out_h5.stem}.parts")


def write_rendering(trajectory_h5: Path, out_h5: Path, obs_mode: str, observe_episode,
                    sensor_configs: dict | None = None, needed: tuple[str, ...] = (), progress=None,
                    tactile_model: int | None = None, part_episodes: int = RENDER_PART_EPISODES) -> tuple[int, int]:
    """Write the re-rendering of stored episodes into ``obs_mode`` observations; return how many
    episodes it holds and how many were rendered now.

    ``observe_episode(seed, states)`` restores each of an episode's recorded env states (flat
    ``env_states`` keys, (T+1, ...) arrays: reset + one per step) in order and returns one flat
    observation per state (:func:`mani_skill_softvt.demonstrations.render.render_observations` does it with the
    env). Observations go to ``traj_<i>/obs/...`` of ``out_h5``, beside the episode's actions,
    flags and attributes (and its source's :func:`episode_digest`), and the trajectory's json is
    written beside it: ``out_h5`` is a ManiSkill trajectory in ``obs_mode`` (with the
    ``sensor_configs`` the env rendered with in its env kwargs, so ManiSkill's tools rebuild the
    same cameras). An episode that a previous ``out_h5`` already holds as current
    (:func:`rendering_current` with ``needed``) is copied from it, not rendered again: a demo set
    that grew renders only its new episodes.

    Episodes are rendered ``part_episodes`` at a time into part files
    (:func:`rendering_parts_dir`), each written atomically, and packed into ``out_h5`` (atomically)
    when all are there; the parts are then removed. A rendering killed mid-task (a session's end)
    keeps its finished parts, and the next run copies them like a previous ``out_h5``'s episodes:
    it loses at most one part's work, not the task's. Two runs must not render one ``out_h5`` at
    once (each would remove the other's parts). The source is checked first.
    ``progress(1)`` is called per episode.
    """
    problem = check_h5(trajectory_h5)  # small (states only): read it all before rendering anything
    if problem:
        raise CorruptDataError(problem)
    if part_episodes < 1:
        raise ValueError(f"part_episodes must be >= 1, got {part_episodes}")
    parts_dir = rendering_parts_dir(out_h5)
    parts = sorted(parts_dir.glob("part_*.h5")) if parts_dir.is_dir() else []
    sources = [f for f in (_open_previous(p) for p in [Path(out_h5), *parts]) if f is not None]
    rendered = 0
    try:
        held = {}  # an episode digest -> a current rendering of it, in out_h5 or a part
        for f in sources:
            for k in f:
                digest = f[k].attrs.get("states_sha256")
                if digest not in held and rendering_current(f[k], digest, needed, tactile_model):
                    held[digest] = f[k]
        with h5py.File(trajectory_h5, "r") as src:
            names = sorted(src.keys(), key=lambda k: int(k.split("_")[1]))
            digests = {name: episode_digest(src[name]) for name in names}
            todo = [name for name in names if digests[name] not in held]
            for _ in range(len(names) - len(todo)):
                if progress is not None:
                    progress(1)
            index = 1 + max((int(p.stem.split("_")[1]) for p in parts), default=-1)
            for start in range(0, len(todo), part_episodes):
                chunk = todo[start:start + part_episodes]

                def write_part(tmp: Path, chunk=chunk):
                    with h5py.File(tmp, "w") as dst:
                        for name in chunk:
                            _render_episode(trajectory_h5, name, src[name], dst, obs_mode, observe_episode,
                                            tactile_model)
                            dst[name].attrs["states_sha256"] = digests[name]
                            dst[name].attrs["render_version"] = RENDER_VERSION
                            if progress is not None:
                                progress(1)

                part = parts_dir / f"part_{index:04d}.h5"
                atomic_write(part, write_part)
                index += 1
                sources.append(h5py.File(part, "r"))
                held.update({digests[name]: sources[-1][name] for name in chunk})
                rendered += len(chunk)

            def write(tmp: Path):
                with h5py.File(tmp, "w") as dst:
                    for name in names:
                        group = held[digests[name]]
                        group.file.copy(group, dst, name=name)  # raw chunks: no re-compression
                        dst[name].attrs.update(dict(src[name].attrs))

            atomic_write(out_h5, write)
    finally:
        for f in sources:
            f.close()
    shutil.rmtree(parts_dir, ignore_errors=True)
    meta_path = Path(trajectory_h5).with_suffix(".json")
    if meta_path.exists():  # the trajectory's json, for the rendered obs mode (ManiSkill pairs them by name)
        meta = read_json(meta_path)
        env_kwargs = meta.setdefault("env_info", {}).setdefault("env_kwargs", {})
        env_kwargs["obs_mode"] = obs_mode
        if sensor_configs:
            env_kwargs["sensor_configs"] = {**env_kwargs.get("sensor_configs", {}), **sensor_configs}
        atomic_write_json(Path(out_h5).with_suffix(".json"), meta)
    return len(names), rendered


def _open_previous(out_h5: Path):
    """A rendering (or a part of one) to copy current episodes from, open for reading; None if
    there is none or it is unreadable (then its episodes are rendered again)."""
    if not Path(out_h5).exists():
        return None
    try:
        return h5py.File(out_h5, "r")
    except OSError:
        return None


def _render_episode(trajectory_h5: Path, name: str, g, dst, obs_mode: str, observe_episode, tactile_model) -> None:
    """Render the stored episode ``g`` into the group ``name`` of ``dst`` (see :func:`write_rendering`)."""
    states = {}
    g["env_states"].visititems(lambda k, v: states.__setitem__(k, v[()]) if isinstance(v, h5py.Dataset) else None)
    steps = {len(v) for v in states.values()}  # one state per step in every group
    if len(steps) != 1:
        raise CorruptDataError(f"{trajectory_h5}:{name}: env_states groups differ in length {sorted(steps)}")
    frames = observe_episode(int(g.attrs["seed"]), states)
    out = dst.create_group(name)
    out.attrs.update(dict(g.attrs))  # seed, instruction, closure, ...
    for k in MANISKILL_STEP_KEYS:  # a ManiSkill trajectory in this obs mode, loadable by its tools
        if k in g:
            _dataset(out, k, g[k][()])
    if tactile_model is not None:
        out.attrs["tactile_model"] = tactile_model
    for k in frames[0]:
        _dataset(out, f"obs/{k}", np.stack([f[k] for f in frames]))


# ---------------------------------------------------------------------- ManiSkill trajectory files
def trajectory_json(h5_path: Path) -> dict:
    """The json of a ManiSkill trajectory file (``<name>.json`` beside ``<name>.h5``), checked for
    what replaying it needs (``env_info`` with ``env_id`` and ``env_kwargs``, ``episodes``); errors
    name the file and what to do."""
    json_path = Path(h5_path).with_suffix(".json")
    if not json_path.exists():
        raise FileNotFoundError(f"{json_path} does not exist: a ManiSkill trajectory is a pair, {Path(h5_path).name} "
                                f"and {json_path.name} (env id, env kwargs, episode seeds); copy the json beside the "
                                f"h5, or record the trajectory again")
    meta = read_json(json_path)
    info = meta.get("env_info")
    if not isinstance(info, dict) or "env_id" not in info or not isinstance(info.get("env_kwargs"), dict) \
            or not isinstance(meta.get("episodes"), list):
        raise ValueError(f"{json_path} is not a ManiSkill trajectory's json (it needs env_info.env_id, "
                         f"env_info.env_kwargs and episodes); record the trajectory again")
    return meta


def trajectory_control_mode(meta: dict) -> str | None:
    """The control mode a trajectory's actions are in (its env kwargs', else its episodes')."""
    mode = meta["env_info"]["env_kwargs"].get("control_mode")
    if mode is None and meta["episodes"]:
        mode = meta["episodes"][0].get("control_mode")
    return mode


def gripper_action_problem(h5_path: Path, meta: dict) -> str | None:
    """Why the gripper actions of a SoftVT trajectory file are not in this version's encoding
    (:data:`~mani_skill_softvt.provenance.GRIPPER_ACTION_VERSION`), naming the command that
    converts it; None if they are. Only the joint and delta modes changed: a ``pd_ee_pose`` file
    is current whatever its version."""
    mode = trajectory_control_mode(meta)
    version = meta["env_info"]["env_kwargs"].get("gripper_action_version", 1)  # unrecorded: written before it was
    try:
        changed = normalized_gripper(mode)
    except ValueError:
        return f"{h5_path}: control mode {mode!r} is not one of SoftVT's; record the trajectory again"
    if not changed or version == GRIPPER_ACTION_VERSION:
        return None
    if version in GRIPPER_ACTION_VERSIONS:
        return f"{h5_path} ({mode}): {GRIPPER_ACTION_VERSIONS[version].format(path=h5_path)}"
    return (f"{h5_path}: gripper_action_version {version!r} is unknown to this version of mani_skill_softvt; "
            f"upgrade the package, or record the trajectory again (`{UPGRADE_COMMAND}` converts version 1 only)")


def upgrade_gripper_actions(h5_path: Path) -> int:
    """Convert a version-1 SoftVT trajectory in a joint or delta mode (gripper closures g in [0, 1])
    to the current encoding in place: its ``actions`` (and ``actions_binary``) gripper column becomes
    ManiSkill's normalised action (1 - 2 g; binary: -1 close, 1 open), its json records
    ``gripper_action_version`` and the task's own env id. Returns how many episodes it converted
    (0: the file was current). The h5 is rewritten atomically; nothing else in it changes."""
    h5_path = Path(h5_path)
    problem = check_h5(h5_path, read=False)
    if problem:
        raise CorruptDataError(problem)
    meta = trajectory_json(h5_path)
    mode = trajectory_control_mode(meta)
    kwargs = meta["env_info"]["env_kwargs"]
    problem = gripper_action_problem(h5_path, meta)
    if problem is None:
        return 0
    try:
        convertible = kwargs.get("gripper_action_version", 1) == 1 and normalized_gripper(mode)
    except ValueError:  # not a SoftVT control mode
        convertible = False
    if not convertible:
        raise ValueError(problem)
    suite, task_id = parse_env_id(meta["env_info"]["env_id"])
    task_id = kwargs.get("task_id", 0) if task_id is None else task_id
    binary_mode = f"{mode.removesuffix('_binary')}_binary"
    episodes = 0

    def write(tmp: Path):
        nonlocal episodes

        shutil.copyfile(h5_path, tmp)
        with h5py.File(tmp, "r+") as f:
            for name in f.keys():
                g = f[name]
                for key, m in (("actions", mode), ("actions_binary", binary_mode)):
                    if key in g:
                        a = g[key][()]
                        a[:, -1] = gripper_action(a[:, -1], m).astype(a.dtype)  # the old values are closures
                        g[key][...] = a
                episodes += 1

    atomic_write(h5_path, write)
    kwargs["gripper_action_version"] = GRIPPER_ACTION_VERSION
    meta["env_info"]["env_id"] = recorded_env_id(suite, int(task_id))
    atomic_write_json(h5_path.with_suffix(".json"), meta)
    return episodes
