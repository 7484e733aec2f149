"""Training windows from rendered expert demonstrations.

Reads each task's trajectory file (actions, binary actions) and its ``rgb+tactile`` rendering
(:class:`~mani_skill_softvt.data.demo_set.DemoSet` finds both) and turns every frame into the
policy's inputs (:mod:`.features`), arrays of all frames (memory-mapped files when cached). Only policy observations
are read, never the ``evaluator/`` group or the env states.

The rendering with the cameras at the config's ``camera_size`` is read when every task has one
(``demos render --camera-size 84x84``), else the smallest larger one every task has (the native
224x224 one at worst), shrunk. Which it was is kept (:attr:`DemoWindows.camera_render_size`,
then in ``policy.pt``), and the evaluator renders the cameras at that size again, so a policy is
evaluated on the images it was trained on.

A sample is the step ``t`` of an episode: the observations of steps ``t-1, t`` (the first step
repeats itself) and the actions ``t .. t+15`` (past the end, the last action repeats: the
expert holds still). The variant picks the gripper column: continuous closure or binary.

Preparing the arrays reads and resizes every image once (minutes for a few hundred demos, about
7 GB for VO's 1,000). The result is cached in a directory (``<cache>/<key>/``: one ``.npy`` per
array and ``meta.json``), keyed by the episodes read and the config's input fields, so a resumed
run skips it and runs that read the same episodes the same way (recipes that differ only in the
optimiser or the network) share one copy. The arrays are written in place through memory maps
and read back memory-mapped: neither preparing nor training holds the frames in memory, and two
runs on one cache share the page cache. A cache is written in a temporary directory renamed into
place at the end, under a lock per key (``flock``, released by the kernel when its holder dies):
a process that finds another preparing the same key waits for it and reads its result, and a
temporary directory left by a process that died is removed. An array that another entry already
holds byte for byte becomes a hard link to that entry's file (:func:`link_shared_arrays`): VO and VT
runs on one demo set share their cameras, state and actions, on disk and in the page cache. The key also names the cache format,
the feature code's version and, for touch, the tactile model and each episode's rendering
version, so a package that reads or renders differently never reads an older entry.
"""

from __future__ import annotations

import errno
import fcntl
import filecmp
import hashlib
import json
import os
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from mani_skill_softvt.data.demo_set import DemoSet
from mani_skill_softvt.data.trajectory import holds_twin_contact, open_h5, tactile_model_of
from mani_skill_softvt.fileio import atomic_write_json, read_json
from mani_skill_softvt.contracts.observations import CAMERAS, NATIVE_CAMERA_SIZE, QPOS, TCP_POSE, camera_key, tactile_keys
from mani_skill_softvt.tasks.suites import get_suite
from .config import DPConfig
from .features import FEATURES_VERSION, frame_features

OBS_MODE = "rgb+tactile"
# Config fields that change the prepared arrays (anything else, e.g. the optimiser, does not).
INPUT_FIELDS = ("variant", "camera_size", "tactile_size", "tactile_inputs", "depth_scale_um", "suite", "tasks",
                "demos_per_task", "heldout_per_task")
CACHE_FORMAT = 2  # the directory of .npy files (1 was one .npz beside the run)


@dataclass
class DemoWindows:
    """Per-frame arrays of all episodes, concatenated; ``starts[i]`` .. ``starts[i+1]`` is episode i."""

    frames: dict[str, np.ndarray]  # per observation frame (T_i + 1 per episode)
    actions: np.ndarray  # (sum T_i, 7) float32, the variant's gripper column
    obs_starts: np.ndarray  # (E + 1,) offsets into frames
    act_starts: np.ndarray  # (E + 1,) offsets into actions
    cfg: DPConfig
    key: str = ""  # cache_key of the sources it was read from (a resumed run checks it)
    camera_render_size: tuple[int, int] = NATIVE_CAMERA_SIZE  # (height, width) the cameras were rendered at
    cache: Path | None = None  # the cache directory it was read from (None: prepared in memory)

    def __len__(self) -> int:
        return int(self.act_starts[-1])

    @property
    def episodes(self) -> int:
        return len(self.act_starts) - 1

    def stats(self) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
        """Min and max per column of the low-dimensional inputs and the actions (normalisers)."""
        out = {"action": self.actions, "state": self.frames["state"]}
        if "markers" in self.frames:
            out["markers"] = self.frames["markers"].reshape(len(self.frames["markers"]), -1)
        return {k: (torch.from_numpy(v.min(0)).float(), torch.from_numpy(v.max(0)).float()) for k, v in out.items()}

    def sample_index(self, i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Global step indices -> (episode, step within the episode)."""
        ep = np.searchsorted(self.act_starts, i, side="right") - 1
        return ep, i - self.act_starts[ep]

    def batch(self, indices: np.ndarray) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """Observation windows (B, obs_horizon, ...) and action chunks (B, action_horizon, 7)."""
        cfg = self.cfg
        ep, t = self.sample_index(np.asarray(indices))
        lengths = self.act_starts[ep + 1] - self.act_starts[ep]
        obs_t = t[:, None] + np.arange(-cfg.obs_horizon + 1, 1)[None]
        obs_rows = self.obs_starts[ep][:, None] + np.clip(obs_t, 0, None)
        act_t = np.minimum(t[:, None] + np.arange(cfg.action_horizon)[None], lengths[:, None] - 1)
        act_rows = self.act_starts[ep][:, None] + act_t
        obs = {k: torch.from_numpy(v[obs_rows]) for k, v in self.frames.items()}
        return obs, torch.from_numpy(self.actions[act_rows])


def render_size_for(camera_size: tuple[int, int], available: list[tuple[int, int]]) -> tuple[int, int]:
    """The camera size to read for a policy that takes ``camera_size``: that size if rendered, else
    the smallest rendered size at least as large both ways (shrunk to it; never enlarged); the
    policy's own size when none is (whose missing file then names the command that renders it)."""
    h, w = camera_size
    larger = [s for s in available if s[0] >= h and s[1] >= w]
    if tuple(camera_size) in available or not larger:
        return tuple(camera_size)
    return min(larger, key=lambda s: (s[0] * s[1], s))


def _sources(cfg: DPConfig, demos_root: Path) -> list[tuple[int, Path, Path]]:
    """(task, trajectory, rendering) of every task, all at the camera size of :func:`render_size_for`
    among the sizes every task is rendered at."""
    demo_set = DemoSet(demos_root, cfg.suite)
    common = set.intersection(*(set(demo_set.rendered_sizes(t, OBS_MODE)) for t in cfg.tasks)) if cfg.tasks else set()
    pairs = demo_set.rendered_sources(list(cfg.tasks), OBS_MODE, render_size_for(cfg.camera_size, sorted(common)))
    return [(task, p.trajectory_h5, p.rendered_h5) for task, p in zip(cfg.tasks, pairs)]


def cache_key(cfg: DPConfig, sources: list[tuple[int, Path, Path]], heldout: bool = False) -> str:
    """What the prepared arrays depend on: the config's input fields and, per task, the episodes
    read. An episode is named by its source's digest (kept in the rendering), so a demo set that
    grew, or files written again with the same episodes, keep the key: a training run resumes
    while step 1 of the campaign goes on. Renderings without digests are named by file."""
    fields = {k: getattr(cfg, k) for k in INPUT_FIELDS}
    code = [CACHE_FORMAT, FEATURES_VERSION, get_suite(cfg.suite).tactile_model if cfg.tactile else None]
    return hashlib.sha256(json.dumps([[_episodes_read(cfg, a, b, heldout) for _, a, b in sources], fields, heldout,
                                      code], default=list).encode()).hexdigest()[:16]


def _episodes_read(cfg: DPConfig, trajectory: Path, rendered: Path, heldout: bool) -> list:
    with open_h5(rendered) as f:
        names = split_episodes(_episode_names(f), cfg, heldout, where=rendered)
        digests = [f[n].attrs.get("states_sha256") for n in names]
        versions = [[int(f[n].attrs.get("render_version", 1)), tactile_model_of(f[n])] for n in names]
    if all(isinstance(d, str) for d in digests):
        return [rendered.name, digests, versions]
    return [(str(p.resolve()), p.stat().st_size, p.stat().st_mtime_ns) for p in (trajectory, rendered)]


def _episode_names(f) -> list[str]:
    return sorted((k for k in f.keys() if k.startswith("traj_")), key=lambda k: int(k.split("_")[1]))


def split_episodes(names: list[str], cfg: DPConfig, heldout: bool = False, where: Path | str = "") -> list[str]:
    """A task's episodes a run trains on, or with ``heldout`` those set aside (never overlapping):
    the first ``demos_per_task`` and the ``heldout_per_task`` after them, so both stay the same
    as the demo set grows; without ``demos_per_task``, all but the last ``heldout_per_task``.
    A task with too few demos for the split (``where``: its file) is an error, not a smaller split."""
    h, n = cfg.heldout_per_task, cfg.demos_per_task
    if h and len(names) < (n or 1) + h:
        raise ValueError(f"{where}: {len(names)} demos, and the run trains on {n or 'at least 1'} and holds out {h} "
                         "after them; generate more demos (demos generate --accepted) or lower demos_per_task")
    n = len(names) - h if n is None else n
    return names[n:n + h] if heldout else names[:n]


def _plan_episodes(cfg: DPConfig, demos_root: Path, heldout: bool) -> tuple[list[tuple], tuple[int, int]]:
    """The episodes to read, checked (observations present, tactile model, frame count, one camera
    size), and the size their cameras were rendered at; reads only the files' metadata."""
    episodes, render_sizes = [], set()
    for task, traj, rendered in _sources(cfg, demos_root):
        with open_h5(traj) as ft, open_h5(rendered) as fr:
            for name in split_episodes(_episode_names(ft), cfg, heldout, where=traj):
                if name not in fr or "obs" not in fr[name]:
                    raise ValueError(f"{rendered}: no observations for {name} of {traj}; re-render task {task}")
                if cfg.tactile and tactile_model_of(fr[name]) != get_suite(cfg.suite).tactile_model:
                    raise ValueError(f"{rendered}:{name}: tactile frames of model {tactile_model_of(fr[name])}, this "
                                     f"package renders {cfg.suite}'s in model {get_suite(cfg.suite).tactile_model}; "
                                     f"re-render with `python -m "
                                     f"mani_skill_softvt.demos render --suite {cfg.suite} --obs-mode {OBS_MODE}`")
                if cfg.tactile and get_suite(cfg.suite).rigid and not holds_twin_contact(ft[name]):
                    raise ValueError(f"{traj}:{name}: recorded without the twins' contact wrenches, so its rendered "
                                     f"touch is a blank gel; record the demos again (`python -m mani_skill_softvt.demos "
                                     f"generate --suite {cfg.suite}`, the episode files moved aside) and re-render")
                obs = fr[name]["obs"]
                n, steps = obs[TCP_POSE].shape[0], ft[name][_action_column(cfg)].shape[0]
                if n != steps + 1:
                    raise ValueError(f"{rendered}:{name}: {n} frames for {steps} actions (expected one more); "
                                     f"the rendering is stale: re-render task {task}")
                render_sizes |= {tuple(int(v) for v in obs[camera_key(c)].shape[1:3]) for c in CAMERAS
                                 if camera_key(c) in obs}
                if len(render_sizes) > 1:
                    raise ValueError(f"{rendered}:{name}: cameras rendered at {sorted(render_sizes)}; the demos a "
                                     "policy learns from share one camera size: render every task at the same size")
                episodes.append((task, traj, rendered, name, n, steps))
    if not episodes:
        which = "held-out demonstrations (heldout_per_task)" if heldout else "demonstrations"
        raise ValueError(f"no {which} found for tasks {cfg.tasks} of {cfg.suite} under {demos_root}")
    return episodes, (render_sizes.pop() if render_sizes else NATIVE_CAMERA_SIZE)


def _episode_features(cfg: DPConfig, task: int, rendered: Path, fr, name: str) -> list[dict[str, np.ndarray]]:
    obs = fr[name]["obs"]
    keys = [k for k in _needed_keys(cfg) if k in obs]
    data = {k: obs[k][()] for k in keys}
    try:
        return [frame_features({k: data[k][i] for k in keys}, cfg) for i in range(obs[TCP_POSE].shape[0])]
    except (KeyError, ValueError) as e:
        raise ValueError(f"{rendered}:{name}: {e}; re-render task {task} with `python -m mani_skill_softvt.demos "
                         f"render --suite {cfg.suite} --tasks {task} --obs-mode {OBS_MODE}` (delete the file first)") from None


def prepare(cfg: DPConfig, demos_root: Path, heldout: bool = False, into: Path | None = None) -> DemoWindows:
    """Read the demonstrations into :class:`DemoWindows` (see the module docstring): the training
    episodes, or with ``heldout`` the held-out ones (:func:`split_episodes`). With ``into`` (a
    directory that must not exist yet) the arrays are ``.npy`` files there, filled in place."""
    episodes, size = _plan_episodes(cfg, demos_root, heldout)
    frame_count, action_count = sum(e[4] for e in episodes), sum(e[5] for e in episodes)
    obs_starts = np.concatenate([[0], np.cumsum([e[4] for e in episodes])])
    act_starts = np.concatenate([[0], np.cumsum([e[5] for e in episodes])])
    if into is not None:
        Path(into).mkdir(parents=True)

    def array(name: str, shape: tuple, dtype) -> np.ndarray:
        if into is None:
            return np.empty(shape, dtype)
        return np.lib.format.open_memmap(Path(into) / f"{name}.npy", mode="w+", dtype=dtype, shape=shape)

    frames: dict[str, np.ndarray] = {}
    actions = array("actions", (action_count, cfg.action_dim), np.float32)
    column = _action_column(cfg)
    for i, (task, traj, rendered, name, n, steps) in enumerate(tqdm(episodes, desc="prepare demos", unit="demo")):
        with open_h5(traj) as ft, open_h5(rendered) as fr:
            actions[act_starts[i]:act_starts[i + 1]] = ft[name][column][()].astype(np.float32)
            for j, features in enumerate(_episode_features(cfg, task, rendered, fr, name)):
                for k, v in features.items():
                    if k not in frames:
                        frames[k] = array(f"frame_{k}", (frame_count, *v.shape), v.dtype)
                    frames[k][obs_starts[i] + j] = v
    for a in (actions, *frames.values()):
        if isinstance(a, np.memmap):
            a.flush()
    return DemoWindows(frames, actions, obs_starts, act_starts, cfg, camera_render_size=size)


def _action_column(cfg: DPConfig) -> str:
    """The trajectory's action column a variant learns: continuous closure or binary."""
    return "actions_binary" if cfg.binary_gripper else "actions"


def _needed_keys(cfg: DPConfig) -> list[str]:
    keys = [QPOS, TCP_POSE, *(camera_key(c) for c in CAMERAS)]
    return keys + (tactile_keys() if cfg.tactile else [])


def data_key(cfg: DPConfig, demos_root: Path, heldout: bool = False) -> str:
    """The cache key of the windows ``cfg`` reads from ``demos_root`` (:func:`cache_key`), without
    reading them: what a resumed run compares with its checkpoint before preparing anything."""
    return cache_key(cfg, _sources(cfg, demos_root), heldout)


def _read_cached(entry: Path, cfg: DPConfig, key: str) -> DemoWindows | None:
    """The memory-mapped windows of a finished cache directory, None if it is not one of ``key``."""
    try:
        meta = read_json(entry / "meta.json")
    except (FileNotFoundError, ValueError):
        return None
    if meta.get("key") != key or meta.get("format") != CACHE_FORMAT:
        return None
    load = lambda name: np.load(entry / f"{name}.npy", mmap_mode="r", allow_pickle=False)
    try:
        frames, actions = {k: load(f"frame_{k}") for k in meta["frames"]}, load("actions")
    except (OSError, ValueError):  # a file missing or damaged: the entry is rebuilt
        return None
    if len(actions) != meta["act_starts"][-1] or any(len(v) != meta["obs_starts"][-1] for v in frames.values()):
        return None
    return DemoWindows(frames, actions, np.asarray(meta["obs_starts"]), np.asarray(meta["act_starts"]), cfg,
                       key, tuple(meta["camera_render_size"]), Path(entry).parent)


def link_shared_arrays(new: Path, cache: Path) -> int:
    """Replace each ``.npy`` of the entry being written in ``new`` that a finished entry of ``cache``
    already holds, byte for byte, by a hard link to that file; returns the bytes now shared. The VO and
    VT variants of one demo set read the same camera frames, state and (per gripper encoding)
    actions: 7.6 of the 14.7 GB a VT entry of 1,000 Object-Soft demos holds. Two trainings at once
    then want one copy of them in the page cache, not two. Entries are only read once renamed into
    place, so a file two entries share is never written through; deleting one entry leaves the
    other's whole. The link is made first and its own bytes compared, so an entry deleted meanwhile
    by another process costs only that file's sharing; a filesystem without hard links keeps the copies."""
    shared = 0
    for f in sorted(new.glob("*.npy")):
        size = f.stat().st_size
        link = f.with_name(f".{f.name}.link")
        for other in sorted(p / f.name for p in cache.iterdir() if p.is_dir() and not p.name.startswith(".")):
            try:
                if other.stat().st_size != size:
                    continue
                os.link(other, link)
            except FileNotFoundError:  # another process removed that entry
                continue
            except OSError as e:
                if e.errno in (errno.EPERM, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK, errno.ENOSYS):
                    return shared  # no hard links here
                raise
            if filecmp.cmp(f, link, shallow=False):  # the inode now linked, not a path that may change
                os.replace(link, f)
                shared += size
                break
            link.unlink()
    return shared


def cache_size_gb(entries: list[Path]) -> float:
    """The disk the ``.npy`` files of ``entries`` take, a file shared by several entries counted once."""
    files = {}
    for p in entries:
        for f in p.glob("*.npy"):
            st = f.stat()
            files[(st.st_dev, st.st_ino)] = st.st_size
    return sum(files.values()) / 2 ** 30


def load_windows(cfg: DPConfig, demos_root: Path, cache: Path | None, heldout: bool = False) -> DemoWindows:
    """:func:`prepare`, through the cache directory ``cache`` when given (see the module docstring):
    the entry of this key if there is one, else prepared into it under the key's lock."""
    key = data_key(cfg, demos_root, heldout)
    if cache is None:
        windows = prepare(cfg, demos_root, heldout)
        windows.key = key
        return windows
    cache = Path(cache)
    if cache.is_file():
        raise ValueError(f"{cache} is a file (a data cache of an older version of this package, one .npz): delete "
                         "it; the cache is now a directory of that name")
    entry = cache / key
    found = _read_cached(entry, cfg, key)  # a finished entry appears whole (renamed into place): no lock needed
    if found is not None:
        return found
    cache.mkdir(parents=True, exist_ok=True)
    with open(cache / f".{key}.lock", "a") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            print(f"waiting for another process preparing {entry}", file=sys.stderr, flush=True)
            fcntl.flock(lock, fcntl.LOCK_EX)
        found = _read_cached(entry, cfg, key)  # the other process's result
        if found is not None:
            return found
        # Holding the lock: whatever else is under this key was left unfinished by a process that died.
        for stale in [entry, *cache.glob(f".{key}.tmp-*")]:
            if stale.exists():
                shutil.rmtree(stale)
        others = [p for p in cache.iterdir() if p.is_dir() and not p.name.startswith(".") and p != entry]
        if others:  # superseded entries (a grown demo set, another split) pile up: say so once per preparation
            size = cache_size_gb(others)
            print(f"preparing {entry}; {len(others)} other entries in {cache} take {size:.1f} GB (each one's meta.json "
                  "says what it holds; delete those no run reads)", file=sys.stderr, flush=True)
        tmp = cache / f".{key}.tmp-{os.getpid()}"
        try:
            windows = prepare(cfg, demos_root, heldout, into=tmp)
            shared = link_shared_arrays(tmp, cache)
            if shared:
                print(f"{entry}: {shared / 2 ** 30:.1f} GB of its arrays are the same as another entry's, shared "
                      "(hard links)", file=sys.stderr, flush=True)
            atomic_write_json(tmp / "meta.json", {
                "format": CACHE_FORMAT, "key": key, "heldout": heldout, "frames": sorted(windows.frames),
                "obs_starts": windows.obs_starts.tolist(), "act_starts": windows.act_starts.tolist(),
                "camera_render_size": list(windows.camera_render_size), "episodes": windows.episodes,
                "inputs": {k: getattr(cfg, k) for k in INPUT_FIELDS}})
            os.replace(tmp, entry)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    found = _read_cached(entry, cfg, key)
    if found is None:
        raise RuntimeError(f"{entry}: the data cache written a moment ago does not read back; delete it and re-run")
    return found
