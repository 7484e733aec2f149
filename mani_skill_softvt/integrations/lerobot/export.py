"""Export rendered expert demonstrations to LeRobot's dataset v3.0 layout (parquet + mp4 + meta).

For users who train with LeRobot or openpi. Input: a ManiSkill trajectory file (``task<k>.h5``,
actions and instruction) and its rendered observations (``task<k>_rgb_tactile.h5``, the output
of ``render_observations``; :class:`~mani_skill_softvt.data.demo_set.DemoSet` finds both). Output, under one root::

    meta/info.json                                  codebase_version "v3.0", fps, features
    meta/stats.json                                 per-feature min/max/mean/std/count/quantiles
    meta/tasks.parquet                              task string (index) -> task_index
    meta/episodes/chunk-000/file-000.parquet        one row per episode: lengths, file offsets, stats
    data/chunk-000/file-000.parquet                 one row per frame
    videos/<video_key>/chunk-000/file-000.mp4       episodes concatenated, h264 yuv420p

Only a whitelist of policy observations is exported (proprioception, camera and tactile images,
tactile marker fields, and each camera's depth where the demos were rendered in an rgbd mode:
``observation.depth.<camera>``, float32 metres (H, W, 1), 0 where nothing was hit); the ``evaluator/`` group (FEM nodes, D_t, R_t, ...) and the env states
are never read, so no privileged quantity can leak into a training set.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import h5py
import imageio.v2 as imageio
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from ...fileio import atomic_write, atomic_write_json
from ...contracts.observations import (
    CAMERAS,
    GRIPPER_WIDTH,
    MARKER_FIELDS,
    NATIVE_CAMERA_SIZE,
    QPOS,
    QVEL,
    SIDES,
    ObsMode,
    TCP_POSE,
    camera_key,
    tactile_key,
)
from ...tactile.constants import IMAGE_HEIGHT, IMAGE_WIDTH, MARKER_COLS, MARKER_ROWS
from ...data.demo_set import Source
from ...data.images import resize_image
from ...data.trajectory import open_h5
from ...tasks.robot import PandaSoftVT

CODEBASE_VERSION = "v3.0"
FPS = 20  # the control frequency: one frame per env step
ROBOT_TYPE = "panda"
CHUNKS_SIZE = 1000  # files per chunk directory (LeRobot's default)
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200
EPISODES_PER_FILE = 100  # one data / video file per 100 episodes keeps data files well under 100 MB
VIDEO_CODEC = "libx264"  # h264 decodes everywhere (torchcodec, PyAV, browsers); LeRobot itself defaults to AV1
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)

ACTION_NAMES = ["x", "y", "z", "rx", "ry", "rz", "gripper"]
# Proprioception concatenated into observation.state, in this order: (rendered key, names prefix).
STATE_PARTS = [(QPOS, "qpos"), (QVEL, "qvel"), (TCP_POSE, "tcp_pose"), (GRIPPER_WIDTH, "gripper_width")]
TCP_POSE_NAMES = ["x", "y", "z", "qw", "qx", "qy", "qz"]
# The LeRobot columns every frame carries (same dtypes as LeRobot's DEFAULT_FEATURES).
INDEX_FEATURES = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}


# ---------------------------------------------------------------------------------------- keys

def video_sources() -> dict[str, str]:
    """LeRobot video key -> rendered observation key (feature names may not contain '/')."""
    out = {f"observation.images.{c}": camera_key(c) for c in CAMERAS}
    out.update({f"observation.images.tactile_{s}": tactile_key(s, "rgb") for s in SIDES})
    return out


def marker_sources() -> dict[str, str]:
    """LeRobot marker feature -> rendered key (an (N, 2) pixel field, flattened to 2N floats)."""
    return {f"observation.tactile.{s}.{m}": tactile_key(s, m) for s in SIDES for m in MARKER_FIELDS}


def depth_sources() -> dict[str, str]:
    """LeRobot depth feature -> rendered key: each camera's depth, in files rendered in an rgbd mode.
    LeRobot has no depth type: exported as numbers, not video (h264 would lose the millimetres)."""
    return {f"observation.depth.{c}": camera_key(c, "depth") for c in CAMERAS}


def depth_metres(depth_mm: np.ndarray, image_size: tuple[int, int] | None = None) -> np.ndarray:
    """ManiSkill's int16 millimetre depth ((..., H, W, 1), 0: nothing hit) as float32 metres, resized
    to ``image_size`` by nearest neighbour: averaging would invent depths between an edge's two sides."""
    d = np.asarray(depth_mm)
    if image_size is not None and d.shape[-3:-1] != tuple(image_size):
        h, w = image_size
        frames = d.reshape(-1, *d.shape[-3:-1])
        d = np.stack([cv2.resize(f, (w, h), interpolation=cv2.INTER_NEAREST) for f in frames])
        d = d.reshape(*depth_mm.shape[:-3], h, w, 1)
    return (d.astype(np.float32) / 1000.0).astype(np.float32)


def frame_features(flat: dict[str, np.ndarray], image_size: tuple[int, int] | None = None) -> dict[str, np.ndarray]:
    """One live observation (flattened, :func:`~mani_skill_softvt.contracts.observations.flatten_batch`) under
    the export's feature names: ``observation.state``, ``observation.images.<camera>`` and
    ``observation.images.tactile_<side>``, ``observation.tactile.<side>.<marker field>``; only those
    the observation has. ``image_size`` resizes every image as the export's ``--image-size`` does
    (None: each stream's own size). A policy trained on the export reads the live env through
    these (:mod:`mani_skill_softvt.integrations.lerobot.env`)."""
    out = {"observation.state": np.concatenate([np.asarray(flat[k]).reshape(-1) for k, _ in STATE_PARTS])
           .astype(np.float32)}
    for feat, key in video_sources().items():
        if key in flat:
            image = np.asarray(flat[key])
            out[feat] = image if image_size is None else resize_image(image, image_size)
    out.update({feat: np.asarray(flat[key]).reshape(-1).astype(np.float32)
                for feat, key in marker_sources().items() if key in flat})
    out.update({feat: depth_metres(flat[key], image_size) for feat, key in depth_sources().items() if key in flat})
    return out


# The obs modes whose frames have these features (the state, camera images, camera depth, touch).
FEATURE_OBS_MODES = ("state_dict", "rgb", "rgb+tactile", "rgbd", "rgbd+tactile")


def frame_feature_shapes(obs_mode: str, camera_size: tuple[int, int] | None = None,
                         image_size: tuple[int, int] | None = None) -> dict[str, tuple[int, ...]]:
    """The shape of each feature :func:`frame_features` gives in ``obs_mode`` with the cameras
    rendered at ``camera_size`` (height, width; None: the native 224x224) and every image resized to
    ``image_size`` (None: not resized), known without building an env."""
    if obs_mode not in FEATURE_OBS_MODES:
        raise ValueError(f"obs mode {obs_mode!r} has no per-stream features; choose one of {FEATURE_OBS_MODES}")
    dof = len(PandaSoftVT.arm_joint_names) + len(PandaSoftVT.gripper_joint_names)
    shapes = {"observation.state": (2 * dof + len(TCP_POSE_NAMES) + 1,)}  # qpos, qvel, tcp pose, jaw gap
    mode = ObsMode.parse(obs_mode)
    h, w = image_size or camera_size or NATIVE_CAMERA_SIZE
    if "rgb" in mode.textures:
        shapes.update({f"observation.images.{c}": (int(h), int(w), 3) for c in CAMERAS})
    if "depth" in mode.textures:
        shapes.update({feat: (int(h), int(w), 1) for feat in depth_sources()})
    if mode.tactile:
        h, w = image_size or (IMAGE_HEIGHT, IMAGE_WIDTH)
        shapes.update({f"observation.images.tactile_{s}": (int(h), int(w), 3) for s in SIDES})
        shapes.update({feat: (2 * MARKER_ROWS * MARKER_COLS,) for feat in marker_sources()})
    return shapes


def required_obs_keys(use_videos: bool) -> list[str]:
    keys = [k for k, _ in STATE_PARTS] + list(marker_sources().values())
    return keys + (list(video_sources().values()) if use_videos else [])


def _traj_names(f: h5py.File) -> list[str]:
    return sorted((k for k in f.keys() if k.startswith("traj_")), key=lambda k: int(k.split("_")[1]))


def _attr_str(v) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


# ---------------------------------------------------------------------------------- validation

def check_episode(name: str, src: h5py.Group, obs: h5py.Group | None, use_videos: bool) -> int:
    """Number of frames T of one episode; ValueError (saying what to do) if the files disagree."""
    if obs is None:
        raise ValueError(f"{name}: the rendered file has no such episode (or no 'obs' group); re-render it with "
                         "`python -m mani_skill_softvt.demos render --obs-mode rgb+tactile` from this trajectory file")
    missing = [k for k in required_obs_keys(use_videos) if k not in obs]
    if missing:
        raise ValueError(f"{name}: rendered observations lack {missing}; render with --obs-mode rgb+tactile "
                         "(or export with --no-video if only the camera images are missing)")
    t = int(src["actions"].shape[0])
    if t == 0:
        raise ValueError(f"{name}: the episode has no steps")
    for k in ("actions_binary", "terminated", "truncated"):
        if src[k].shape[0] != t:
            raise ValueError(f"{name}: {k} has {src[k].shape[0]} steps, actions {t}; regenerate the demos")
    for k in required_obs_keys(use_videos):
        if obs[k].shape[0] != t + 1:
            raise ValueError(f"{name}: rendered {k} has {obs[k].shape[0]} frames, expected {t + 1} (reset + one per "
                             "action); the rendered file is stale or from another trajectory file: re-render it")
    return t


def check_shapes(name: str, cols: dict[str, np.ndarray], obs: h5py.Group, features: dict, use_videos: bool) -> None:
    """Every episode must match the features taken from the first one (one table, one mp4 per file)."""
    for f, ft in features.items():
        if ft["dtype"] != "video" and ft["shape"] != [1] and cols[f].shape[1:] != tuple(ft["shape"]):
            raise ValueError(f"{name}: {f} has shape {cols[f].shape[1:]}, the first episode {ft['shape']}; "
                             "export episodes of one robot and one tactile sensor configuration together")
    if use_videos:
        for vk, key in video_sources().items():
            if list(obs[key].shape[1:]) != features[vk]["shape"]:
                raise ValueError(f"{name}: {key} frames are {obs[key].shape[1:]}, the first episode's "
                                 f"{features[vk]['shape']}; export episodes rendered at one resolution together")


# ----------------------------------------------------------------------------- frame columns

def state_names(dims: dict[str, int]) -> list[str]:
    """Names of the observation.state entries, given each part's width."""
    names = []
    for key, prefix in STATE_PARTS:
        if prefix == "tcp_pose" and dims[key] == len(TCP_POSE_NAMES):
            names += [f"tcp_{n}" for n in TCP_POSE_NAMES]
        elif dims[key] == 1:
            names.append(prefix)
        else:
            names += [f"{prefix}_{i}" for i in range(dims[key])]
    return names


def episode_columns(src: h5py.Group, obs: h5py.Group, t: int, episode_index: int, task_index: int,
                    start_index: int, fps: int, image_size: tuple[int, int] | None = None) -> dict[str, np.ndarray]:
    """The non-video columns of one episode, T rows (camera depth resized to ``image_size``).

    Frame t pairs the observation *before* action t with action t (LeRobot's convention), so the
    last rendered observation (after the final action) has no row.
    """
    frame = np.arange(t, dtype=np.int64)
    cols = {
        "observation.state": np.concatenate([obs[k][:t].reshape(t, -1) for k, _ in STATE_PARTS], 1).astype(np.float32),
        "action": src["actions"][()].astype(np.float32),
        "action_binary": src["actions_binary"][()].astype(np.float32),
    }
    for feat, key in marker_sources().items():
        cols[feat] = obs[key][:t].reshape(t, -1).astype(np.float32)
    for feat, key in depth_sources().items():
        if key in obs:  # rendered in an rgbd mode
            cols[feat] = depth_metres(obs[key][:t], image_size)
    done = np.zeros(t, bool)
    done[-1] = True  # the stored episode ends at its last action (terminated, truncated or expert done)
    cols["next.done"] = done
    cols["timestamp"] = (frame / fps).astype(np.float32)
    cols["frame_index"] = frame
    cols["episode_index"] = np.full(t, episode_index, np.int64)
    cols["index"] = start_index + frame
    cols["task_index"] = np.full(t, task_index, np.int64)
    return cols


def numeric_features(cols: dict[str, np.ndarray], names_state: list[str]) -> dict[str, dict]:
    """info.json ``features`` entries of the non-image columns."""
    feats = {
        "observation.state": {"dtype": "float32", "shape": [cols["observation.state"].shape[1]], "names": names_state},
        "action": {"dtype": "float32", "shape": [7], "names": ACTION_NAMES},
        "action_binary": {"dtype": "float32", "shape": [7], "names": ACTION_NAMES},
    }
    for feat in marker_sources():
        n = cols[feat].shape[1] // 2
        feats[feat] = {"dtype": "float32", "shape": [2 * n], "names": [f"m{i}_{a}" for i in range(n) for a in "uv"]}
    for feat in depth_sources():
        if feat in cols:
            feats[feat] = {"dtype": "float32", "shape": list(cols[feat].shape[1:]), "names": ["height", "width", "channels"],
                           "info": {"unit": "m", "missing": 0.0, "source": "ManiSkill depth, int16 mm along the optical axis"}}
    feats["next.done"] = {"dtype": "bool", "shape": [1], "names": None}
    return {**feats, **INDEX_FEATURES}


def video_feature(height: int, width: int, fps: int) -> dict:
    return {"dtype": "video", "shape": [height, width, 3], "names": ["height", "width", "channels"],
            "info": {"video.height": height, "video.width": width, "video.codec": "h264", "video.pix_fmt": "yuv420p",
                     "video.is_depth_map": False, "video.fps": fps, "video.channels": 3, "has_audio": False}}


# ------------------------------------------------------------------------------------- stats

def feature_stats(x: np.ndarray, shape=None) -> dict[str, np.ndarray]:
    """LeRobot's per-feature statistics over the frame axis (plus quantiles, used by pi0.5 / openpi),
    one per element, in the feature's ``shape`` where it has several axes (a depth map's per pixel)."""
    x = np.asarray(x, np.float64).reshape(len(x), -1)
    out = {"min": x.min(0), "max": x.max(0), "mean": x.mean(0), "std": x.std(0)}
    for q in QUANTILES:
        out[f"q{round(q * 100):02d}"] = np.quantile(x, q, axis=0)
    if shape is not None and len(shape) > 1:
        out = {k: v.reshape(shape) for k, v in out.items()}
    out["count"] = np.array([len(x)])
    return out


def image_stats(frames, length: int, max_samples: int = 100) -> dict[str, np.ndarray]:
    """Per-channel stats in [0, 1], shape (3, 1, 1), over up to ``max_samples`` evenly spaced frames
    of the first ``length``; ``frames`` may be an h5py dataset (only the sampled frames are read)."""
    idx = np.unique(np.round(np.linspace(0, length - 1, min(max_samples, length))).astype(int))
    x = np.asarray(frames[idx], np.float64)[:, ::2, ::2] / 255.0  # halve resolution: stats, not pixels
    x = x.transpose(3, 0, 1, 2).reshape(3, -1)
    out = {"min": x.min(1), "max": x.max(1), "mean": x.mean(1), "std": x.std(1)}
    out.update({f"q{round(q * 100):02d}": np.quantile(x, q, axis=1) for q in QUANTILES})
    out = {k: v.reshape(3, 1, 1) for k, v in out.items()}
    out["count"] = np.array([length])
    return out


def aggregate_stats(per_episode: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Count-weighted merge of per-episode stats (exact for mean and std; quantiles are weighted means)."""
    counts = np.array([s["count"][0] for s in per_episode], np.float64)
    w = counts / counts.sum()
    shape = (-1,) + (1,) * (np.asarray(per_episode[0]["mean"]).ndim)
    means = np.stack([s["mean"] for s in per_episode])
    mean = (means * w.reshape(shape)).sum(0)
    var = ((np.stack([s["std"] for s in per_episode]) ** 2 + (means - mean) ** 2) * w.reshape(shape)).sum(0)
    out = {"min": np.min([s["min"] for s in per_episode], 0), "max": np.max([s["max"] for s in per_episode], 0),
           "mean": mean, "std": np.sqrt(var), "count": np.array([int(counts.sum())])}
    for k in per_episode[0]:
        if k.startswith("q"):  # no exact merge from summaries; LeRobot approximates the same way
            out[k] = (np.stack([s[k] for s in per_episode]) * w.reshape(shape)).sum(0)
    return out


def _jsonable(stats: dict[str, dict[str, np.ndarray]]) -> dict:
    return {f: {k: np.asarray(v).tolist() for k, v in s.items()} for f, s in stats.items()}


# ----------------------------------------------------------------------------------- writing

def _arrow_table(cols: dict[str, np.ndarray], features: dict[str, dict]):
    """Columns as an Arrow table: scalars as plain columns, vectors as fixed-size lists."""
    arrays, names = [], []
    for name, ft in features.items():
        if ft["dtype"] == "video":
            continue
        x = np.ascontiguousarray(cols[name])
        if ft["shape"] == [1]:
            arrays.append(pa.array(x.reshape(-1)))
        else:
            nested = pa.array(x.reshape(-1))
            for size in reversed(ft["shape"]):  # (T, H, W, 1): lists of H lists of W lists of 1
                nested = pa.FixedSizeListArray.from_arrays(nested, size)
            arrays.append(nested)
        names.append(name)
    return pa.Table.from_arrays(arrays, names=names)


def _write_parquet(path: Path, table) -> None:
    atomic_write(path, lambda tmp: pq.write_table(table, tmp, compression="snappy"))


def tasks_table(tasks: list[str]):
    """meta/tasks.parquet as pandas writes it (task strings as the index named "task"), built with
    pyarrow alone; LeRobot reads it with ``pd.read_parquet`` and looks tasks up by index."""
    pandas_meta = {
        "index_columns": ["task"],
        "column_indexes": [{"name": None, "field_name": None, "pandas_type": "unicode", "numpy_type": "object",
                            "metadata": {"encoding": "UTF-8"}}],
        "columns": [{"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64",
                     "metadata": None},
                    {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object",
                     "metadata": None}],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }
    table = pa.table({"task_index": pa.array(range(len(tasks)), pa.int64()), "task": pa.array(tasks, pa.string())})
    return table.replace_schema_metadata({b"pandas": json.dumps(pandas_meta).encode()})


def encode_video(path: Path, frames, fps: int) -> int:
    """Encode uint8 (H, W, 3) frames to an h264 mp4 (atomically); return the frame count."""
    n = 0

    def write(tmp: Path):
        nonlocal n
        # -g 2: a keyframe every 2 frames, so random access (LeRobot decodes single frames) stays cheap.
        w = imageio.get_writer(tmp, format="FFMPEG", mode="I", fps=fps, codec=VIDEO_CODEC, pixelformat="yuv420p",
                               macro_block_size=1, ffmpeg_log_level="error", ffmpeg_params=["-g", "2", "-crf", "23"])
        try:
            for f in frames:
                w.append_data(f)
                n += 1
        finally:
            w.close()
    atomic_write(path, write)
    return n


# ------------------------------------------------------------------------------------ export

def _short(path: Path) -> str:
    path = Path(path)
    return f"{path.parent.name}/{path.name}"


def _chunk_file(file_number: int) -> tuple[int, int]:
    return file_number // CHUNKS_SIZE, file_number % CHUNKS_SIZE


def _data_path(kind: str, chunk: int, file: int, video_key: str = "") -> str:
    if kind == "video":
        return f"videos/{video_key}/chunk-{chunk:03d}/file-{file:03d}.mp4"
    return f"{kind}/chunk-{chunk:03d}/file-{file:03d}.parquet"


def _plan(sources: list[Source], use_videos: bool) -> list[dict]:
    """Validate every episode up front (fail before writing anything); one entry per episode."""
    episodes = []
    for s in sources:
        for p in (s.trajectory_h5, s.rendered_h5):
            if not Path(p).exists():
                raise FileNotFoundError(f"{p} does not exist; generate and render the demos first")
        with open_h5(s.trajectory_h5) as src, open_h5(s.rendered_h5) as ren:
            names = _traj_names(src)
            if not names:
                raise ValueError(f"{s.trajectory_h5} holds no traj_<i> episodes")
            extra = sorted(set(_traj_names(ren)) - set(names))
            if extra:
                raise ValueError(f"{s.rendered_h5} has episodes {extra} missing from {s.trajectory_h5}: "
                                 "it was rendered from another trajectory file; re-render it")
            for name in names:
                obs = ren[name]["obs"] if name in ren and "obs" in ren[name] else None
                t = check_episode(f"{s.rendered_h5}:{name}", src[name], obs, use_videos)
                instruction = _attr_str(src[name].attrs["instruction"])
                if "instruction" in ren[name].attrs and _attr_str(ren[name].attrs["instruction"]) != instruction:
                    raise ValueError(f"{s.rendered_h5}:{name}: instruction differs from {s.trajectory_h5}; "
                                     "re-render it")
                episodes.append({"source": s, "traj": name, "length": t, "instruction": instruction,
                                 "seed": int(src[name].attrs["seed"])})
    return episodes


def export_lerobot(sources: list[Source], out_dir: Path, use_videos: bool = True, fps: int = FPS,
                   episodes_per_file: int = EPISODES_PER_FILE, robot_type: str = ROBOT_TYPE,
                   image_size: tuple[int, int] | None = None) -> dict:
    """Write the LeRobot v3.0 dataset of ``sources`` under ``out_dir`` (which must be empty); return info.json.

    ``use_videos=False`` omits the image features entirely (no mp4, no video_path), e.g. for a
    tiny sample. ``image_size`` = (height, width) resizes every image stream, cameras and tactile,
    to one size (area averaging); LeRobot's stock Diffusion Policy needs all its image inputs the
    same shape, and the GelSight's 240x320 is not the cameras' 224x224. None keeps each stream's
    own size. Every file is written atomically and ``meta/info.json`` last, so a directory
    with an info.json is a complete dataset.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and any(out_dir.iterdir()):
        raise ValueError(f"{out_dir} is not empty; export into a new directory (or delete this one first)")
    if episodes_per_file < 1:
        raise ValueError("episodes_per_file must be >= 1")
    if image_size is not None and (len(image_size) != 2 or min(image_size) < 8):
        raise ValueError(f"image_size {image_size}: give (height, width), each at least 8 pixels")
    episodes = _plan(list(sources), use_videos)
    if not episodes:
        raise ValueError("nothing to export: no episodes in the given sources")
    tasks = list(dict.fromkeys(e["instruction"] for e in episodes))
    task_index = {t: i for i, t in enumerate(tasks)}

    features, ep_rows, ep_stats = None, [], []
    start = 0
    groups = [episodes[i:i + episodes_per_file] for i in range(0, len(episodes), episodes_per_file)]
    for file_number, group in enumerate(groups):
        chunk, file = _chunk_file(file_number)
        tables = []
        for ep in group:
            ep_index = len(ep_rows)
            cols, stats, features = _read_episode(ep, ep_index, task_index[ep["instruction"]], start, fps, features,
                                                  use_videos, image_size)
            tables.append(_arrow_table(cols, features))
            t = ep["length"]
            row = {"episode_index": ep_index, "tasks": [ep["instruction"]], "length": t,
                   "data/chunk_index": chunk, "data/file_index": file,
                   "dataset_from_index": start, "dataset_to_index": start + t,
                   "meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0}
            ep_rows.append(row)
            ep_stats.append(stats)
            start += t
        _write_parquet(out_dir / _data_path("data", chunk, file), pa.concat_tables(tables))
        if use_videos:
            for vk, key in video_sources().items():
                _write_episode_videos(out_dir, vk, key, group, ep_rows[-len(group):], chunk, file, fps, image_size)

    _write_episodes_meta(out_dir, ep_rows, ep_stats)
    global_stats = {f: aggregate_stats([s[f] for s in ep_stats]) for f in ep_stats[0]}
    atomic_write_json(out_dir / "meta" / "stats.json", _jsonable(global_stats))
    _write_parquet(out_dir / "meta" / "tasks.parquet", tasks_table(tasks))
    # Suite-relative names only: absolute local paths do not belong in a shareable dataset.
    provenance = [{"episode_index": r["episode_index"], "trajectory_h5": _short(e["source"].trajectory_h5),
                   "traj": e["traj"], "seed": e["seed"]} for r, e in zip(ep_rows, episodes)]
    atomic_write_json(out_dir / "meta" / "softvt_source.json", {"episodes": provenance, "frame_convention":
                      "row t = observation before action t; the final observation (after the last action) is dropped"})
    info = {
        "codebase_version": CODEBASE_VERSION, "robot_type": robot_type,
        "total_episodes": len(ep_rows), "total_frames": start, "total_tasks": len(tasks),
        "chunks_size": CHUNKS_SIZE, "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB,
        "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB, "fps": fps, "splits": {"train": f"0:{len(ep_rows)}"},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4" if use_videos else None,
        "features": features,
    }
    atomic_write_json(out_dir / "meta" / "info.json", info)
    return info


def _read_episode(ep: dict, ep_index: int, task_index: int, start: int, fps: int, features: dict | None,
                  use_videos: bool, image_size: tuple[int, int] | None = None) -> tuple[dict, dict, dict]:
    """One episode's columns and stats; ``features`` are taken from the first episode, then enforced."""
    with open_h5(ep["source"].trajectory_h5) as src, open_h5(ep["source"].rendered_h5) as ren:
        obs, t = ren[ep["traj"]]["obs"], ep["length"]
        cols = episode_columns(src[ep["traj"]], obs, t, ep_index, task_index, start, fps, image_size)
        if features is None:
            features = numeric_features(cols, state_names({k: int(np.prod(obs[k].shape[1:])) for k, _ in STATE_PARTS}))
            if use_videos:
                for vk, key in video_sources().items():
                    h, w = image_size or (int(obs[key].shape[1]), int(obs[key].shape[2]))
                    features[vk] = video_feature(h, w, fps)
        check_shapes(f"{ep['source'].rendered_h5}:{ep['traj']}", cols, obs, features, use_videos and image_size is None)
        stats = {f: feature_stats(cols[f], features[f]["shape"]) for f in features if features[f]["dtype"] != "video"}
        if use_videos:
            stats.update({vk: image_stats(obs[key], t) for vk, key in video_sources().items()})
    return cols, stats, features


def _write_episode_videos(out_dir: Path, video_key: str, obs_key: str, group: list[dict], rows: list[dict],
                          chunk: int, file: int, fps: int, image_size: tuple[int, int] | None = None) -> None:
    """One mp4 per (video key, file) with the group's episodes back to back; fills the rows' offsets."""
    def frames():
        for ep in group:
            with open_h5(ep["source"].rendered_h5) as ren:
                data = ren[ep["traj"]]["obs"][obs_key]
                for i in range(ep["length"]):  # T frames, as in the data file
                    f = data[i]
                    yield f if image_size is None else resize_image(f, image_size)

    n = encode_video(out_dir / _data_path("video", chunk, file, video_key), frames(), fps)
    if n != sum(ep["length"] for ep in group):
        raise RuntimeError(f"encoded {n} frames for {video_key}, expected {sum(ep['length'] for ep in group)}")
    t0 = 0.0
    for ep, row in zip(group, rows):
        row[f"videos/{video_key}/chunk_index"] = chunk
        row[f"videos/{video_key}/file_index"] = file
        row[f"videos/{video_key}/from_timestamp"] = t0
        t0 += ep["length"] / fps
        row[f"videos/{video_key}/to_timestamp"] = t0


def _write_episodes_meta(out_dir: Path, rows: list[dict], stats: list[dict]) -> None:
    """meta/episodes/chunk-000/file-000.parquet: offsets per episode plus flattened ``stats/<feature>/<stat>``."""
    cols: dict[str, list] = {k: [r[k] for r in rows] for k in rows[0]}
    for f in stats[0]:
        for k in stats[0][f]:
            cols[f"stats/{f}/{k}"] = [np.asarray(s[f][k]).tolist() for s in stats]
    table = pa.table(cols)
    _write_parquet(out_dir / "meta" / "episodes" / "chunk-000" / "file-000.parquet", table)


__all__ = ["Source", "export_lerobot", "feature_stats", "image_stats", "aggregate_stats",
           "tasks_table", "video_sources", "marker_sources", "depth_sources"]
