"""The on-disk layout of one suite's demonstrations, in one place.

::

    <root>/<suite>/manifest.json               seed ranges (training, ID evaluation), the expert's planner, the
                                               recorded control mode, the physics signature
    <root>/<suite>/task<k>/ep_<seed>.h5/.json  one accepted episode, ManiSkill's format (written as it finishes: resume)
    <root>/<suite>/task<k>/qc.jsonl            the screening verdict of every generated episode
    <root>/<suite>/task<k>.h5 / .json          accepted episodes in ManiSkill's trajectory format
    <root>/<suite>/task<k>_<obs_mode>.h5       the same episodes re-rendered into observations
    <root>/<suite>/task<k>_<obs_mode>_<H>x<W>.h5   ... with the cameras rendered at H x W (not 224 x 224)
    <root>/<suite>/task<k>_<obs_mode>[_<H>x<W>].parts/part_<j>.h5   a rendering under way, ten episodes a part
                                               (removed when the task's file is written)
    <root>/<suite>/qc_report.json, stats.json, r_max_hist.png
    <root>/<suite>/.task<k>.lock               held while a process records, merges or renders task k
    <root>/<suite>/.suite.lock                 held while a process rewrites the manifest or the QC report

Generation (:mod:`mani_skill_softvt.demos`), rendering, the LeRobot export and the statistics
all find their files through :class:`DemoSet`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from ..fileio import file_lock, read_jsonl
from ..contracts.observations import NATIVE_CAMERA_SIZE, camera_size_name, is_native_camera_size
from ..tasks.suites import NUM_TASKS, get_suite


def latest_verdicts(qc_log: list[dict]) -> list[dict]:
    """One screening record per seed, its latest (an episode recorded again on another machine
    appends a second line), in the order the seeds were first logged."""
    return list({r["seed"]: r for r in qc_log}.values())


@dataclass(frozen=True)
class Source:
    """One task's trajectory file and its rendered observations: what training and the LeRobot
    export read (:meth:`DemoSet.rendered_sources`)."""

    trajectory_h5: Path
    rendered_h5: Path


@dataclass(frozen=True)
class DemoSet:
    """The demonstrations of ``suite`` under ``root`` (see the module docstring)."""

    root: Path
    suite: str

    def __post_init__(self):
        get_suite(self.suite)  # a clear error for an unknown suite
        object.__setattr__(self, "root", Path(self.root))

    @property
    def dir(self) -> Path:
        return self.root / self.suite

    @property
    def manifest(self) -> Path:
        return self.dir / "manifest.json"

    @property
    def qc_report(self) -> Path:
        return self.dir / "qc_report.json"

    @property
    def stats(self) -> Path:
        return self.dir / "stats.json"

    @property
    def r_max_histogram(self) -> Path:
        return self.dir / "r_max_hist.png"

    def episode_dir(self, task_id: int) -> Path:
        return self.dir / f"task{task_id}"

    def episode_file(self, task_id: int, seed: int) -> Path:
        return self.episode_dir(task_id) / f"ep_{seed}.h5"

    def qc_log(self, task_id: int) -> Path:
        return self.episode_dir(task_id) / "qc.jsonl"

    def read_qc(self, task_id: int) -> list[dict]:
        """The screening records of a task's generated episodes, as logged (empty if none)."""
        return read_jsonl(self.qc_log(task_id))

    def verdicts(self, task_id: int) -> list[dict]:
        """The task's :func:`latest_verdicts`."""
        return latest_verdicts(self.read_qc(task_id))

    def accepted_listed(self, task_id: int) -> int:
        """The accepted seeds the task's QC log lists, their episode files here or not (generate
        records a listed one again where its file is missing, whatever number it is asked for)."""
        return sum(bool(r["accepted"]) for r in self.verdicts(task_id))

    def task_lock(self, task_id: int):
        """A context that holds task ``task_id``'s lock: one process at a time records, merges or
        renders a task's files. Two runs over one suite (the campaign's two lanes, one going from
        the first task and one from the last) then share its tasks: each waits for a task the other
        holds and finds it done."""
        return file_lock(self.dir / f".task{task_id}.lock")

    def suite_lock(self):
        """A context that holds the suite's lock, for the files every task's run rewrites (the
        manifest, the QC report)."""
        return file_lock(self.dir / ".suite.lock")

    def trajectory(self, task_id: int) -> Path:
        """The task's accepted episodes, ManiSkill trajectory file (its ``.json`` sits beside it)."""
        return self.dir / f"task{task_id}.h5"

    def rendered(self, task_id: int, obs_mode: str, camera_size: tuple[int, int] | None = None) -> Path:
        """The task's episodes re-rendered into ``obs_mode`` observations, the cameras at
        ``camera_size`` = (height, width) (None: the native 224x224)."""
        size = "" if is_native_camera_size(camera_size) else f"_{camera_size_name(camera_size)}"
        return self.dir / f"task{task_id}_{obs_mode.replace('+', '_')}{size}.h5"

    def rendered_sizes(self, task_id: int, obs_mode: str) -> list[tuple[int, int]]:
        """The camera sizes (height, width) the task's episodes are rendered at in ``obs_mode``."""
        stem = f"task{task_id}_{obs_mode.replace('+', '_')}"
        sizes = [NATIVE_CAMERA_SIZE] if self.rendered(task_id, obs_mode).exists() else []
        for p in self.dir.glob(f"{stem}_*x*.h5"):
            m = re.fullmatch(rf"{re.escape(stem)}_(\d+)x(\d+)\.h5", p.name)
            if m:
                sizes.append((int(m[1]), int(m[2])))
        return sorted(set(sizes))

    def renderings(self, task_id: int) -> list[Path]:
        """Every rendering of the task's episodes on disk, whatever its obs mode."""
        return sorted(self.dir.glob(f"task{task_id}_*.h5"))

    def tasks_with_trajectories(self) -> list[int]:
        return [t for t in range(NUM_TASKS) if self.trajectory(t).exists()]

    def rendered_sources(self, tasks: list[int], obs_mode: str = "rgb+tactile",
                         camera_size: tuple[int, int] | None = None) -> list:
        """The (trajectory, rendered) pairs of ``tasks`` (the LeRobot export's and the baselines'
        training input), the renderings with cameras at ``camera_size``; a missing file is named
        with the command that writes it."""
        size = "" if is_native_camera_size(camera_size) else f" --camera-size {camera_size_name(camera_size)}"
        out = []
        for t in tasks:
            traj, rendered = self.trajectory(t), self.rendered(t, obs_mode, camera_size)
            if not traj.exists():
                raise FileNotFoundError(f"{traj} does not exist; run `python -m mani_skill_softvt.demos generate "
                                        f"--suite {self.suite} --tasks {t} --out {self.root}` first")
            if not rendered.exists():
                raise FileNotFoundError(f"{rendered} does not exist; run `python -m mani_skill_softvt.demos render "
                                        f"--suite {self.suite} --tasks {t} --obs-mode {obs_mode}{size} --out {self.root}` "
                                        "first")
            out.append(Source(traj, rendered))
        return out
