"""ManiSkill's diffusion-policy baseline on a SoftVT demo, as a ManiSkill user runs it (docs/maniskill.md):
motion planning -> ``replay -c pd_ee_delta_pose`` -> ManiSkill's own ``train_rgbd.py`` (rgb) and
``train.py`` (state), a few iterations each with one evaluation episode before and one after, on the
CPU -> the rgb checkpoint scored by ``python -m mani_skill_softvt.evaluate``
(:class:`~mani_skill_softvt.evaluation.maniskill_dp.ManiSkillDiffusionPolicy`).

ManiSkill's baselines are not in its wheel: point ``SOFTVT_MANISKILL_DP_DIR`` at a checkout's
``examples/baselines/diffusion_policy`` (the folder holding ``train_rgbd.py``). The scripts also need
``diffusers``, ``tyro`` and ``tensorboard`` (``pip install 'mani-skill-softvt[maniskill-baselines]'``).

The scripts run unchanged but for one line: under gymnasium >= 1.0 their ``evaluate`` reads
``info["final_info"]``, which CPU vector envs no longer return (ManiSkill's own PickCube-v1 fails
the same way). The test applies, to a copy of ``diffusion_policy/evaluate.py``, the one-line fix
docs/maniskill.md gives users (:data:`EVALUATE_FIX`), if the checkout still needs it.
"""

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

DP_DIR = os.environ.get("SOFTVT_MANISKILL_DP_DIR")
MISSING = [m for m in ("diffusers", "tyro", "tensorboard") if importlib.util.find_spec(m) is None]

# What runs ManiSkill's scripts: slow, and skipped (saying why) without the scripts or what they import.
BASELINE = [
    pytest.mark.slow,
    pytest.mark.skipif(not DP_DIR, reason="SOFTVT_MANISKILL_DP_DIR is not set: point it at ManiSkill's "
                                          "examples/baselines/diffusion_policy (the folder holding train_rgbd.py)"),
    pytest.mark.skipif(bool(MISSING), reason=f"ManiSkill's baseline scripts need {', '.join(MISSING)}: "
                                             "pip install 'mani-skill-softvt[maniskill-baselines]'"),
]


def baseline(f):
    for mark in reversed(BASELINE):
        f = mark(f)
    return f

ENV_ID = "SoftVTObjectSoft-Task3-v1"  # the cream-coloured cube: the task the user trained on
# The fix docs/maniskill.md gives: the step that ends the episodes returns their final info itself
# (gymnasium >= 1.0), so evaluate's loop gets it as gymnasium 0.29 gave it. Inserted before ANCHOR.
ANCHOR = 'if isinstance(info["final_info"], dict):'
EVALUATE_FIX = ('info.setdefault("final_info", [{"episode": {k: v[i] for k, v in info["episode"].items() '
                'if not k.startswith("_")}} for i in range(eval_envs.num_envs)])  # gymnasium >= 1.0')


def _run(cmd: list[str], cwd: Path, timeout: int = 1800) -> str:
    """A command as the user types it, in a fresh process. One torch thread: beside another busy
    process, two threads make ManiSkill's 1-D U-Net ~100x slower on a 2-core CPU (docs/maniskill.md)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, (proc.stdout[-2000:], proc.stderr[-4000:])
    return proc.stdout


@pytest.fixture(scope="module")
def dp_dir(tmp_path_factory) -> Path:
    """A copy of the user's ManiSkill baseline folder, with :data:`EVALUATE_FIX` if it still reads
    ``final_info`` unguarded; the scripts themselves are not touched."""
    src = Path(DP_DIR)
    if not (src / "train_rgbd.py").exists():
        pytest.fail(f"SOFTVT_MANISKILL_DP_DIR={src} holds no train_rgbd.py; point it at ManiSkill's "
                    f"examples/baselines/diffusion_policy")
    dst = tmp_path_factory.mktemp("maniskill_dp") / "diffusion_policy_baseline"
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("runs", "wandb", "__pycache__"))
    evaluate = dst / "diffusion_policy" / "evaluate.py"
    text = evaluate.read_text()
    if "final_info" in text and "setdefault(\"final_info\"" not in text:
        assert ANCHOR in text, f"{evaluate}: the documented final_info fix does not apply to this version"
        lines = []
        for line in text.splitlines(keepends=True):
            if line.strip() == ANCHOR:
                lines.append(line[: len(line) - len(line.lstrip())] + EVALUATE_FIX + "\n")
            lines.append(line)
        evaluate.write_text("".join(lines))
    return dst


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> dict[str, Path]:
    """One soft-cube motion-planning demo, converted to pd_ee_delta_pose with rgb observations, and
    that file replayed into state observations: the commands of docs/maniskill.md."""
    from mani_skill_softvt.expert.planner import MPLIB_PLANS, MPLIB_UNAVAILABLE

    if not MPLIB_PLANS:
        pytest.skip(MPLIB_UNAVAILABLE)
    # No "rgbd" in the path: train_rgbd.py expects depth images when its demo path contains it.
    work = tmp_path_factory.mktemp("user")
    py = sys.executable
    _run([py, "-m", "mani_skill_softvt.integrations.maniskill.motionplanning", "-e", ENV_ID, "-n", "1", "--only-count-success"], work)
    mp = work / "demos" / ENV_ID / "motionplanning" / "task3.h5"
    _run([py, "-m", "mani_skill_softvt.integrations.maniskill.replay", "--traj-path", str(mp), "-c", "pd_ee_delta_pose", "-o", "rgb",
          "--save-traj"], work)
    rgb = mp.with_name("task3.rgb.pd_ee_delta_pose.physx_cpu.h5")
    _run([py, "-m", "mani_skill_softvt.integrations.maniskill.replay", "--traj-path", str(rgb), "-o", "state", "--save-traj"], work)
    return {"work": work, "rgb": rgb, "state": mp.with_name("task3.state.pd_ee_delta_pose.physx_cpu.h5")}


def _common_flags(demo: Path) -> list[str]:
    # The env id the converted file records: the task's own id, module-qualified (the script never
    # imports our package; gymnasium does, from the prefix).
    env_id = json.loads(demo.with_suffix(".json").read_text())["env_info"]["env_id"]
    assert env_id == f"mani_skill_softvt:{ENV_ID}"
    return ["--env-id", env_id, "--demo-path", str(demo), "--control-mode", "pd_ee_delta_pose",
            # --eval-freq = --total-iters: the script evaluates at iteration 0 and after the last one.
            "--sim-backend", "physx_cpu", "--max-episode-steps", "8", "--total-iters", "20", "--batch-size", "8",
            "--num-eval-episodes", "1", "--num-eval-envs", "1", "--eval-freq", "20", "--log-freq", "5",
            "--save-freq", "10", "--no-capture-video", "--no-cuda"]


def _check_run(out: str, run_dir: Path) -> None:
    # The script evaluated twice (at iteration 0 and at the end), one 8-step episode each, logged and
    # saved its checkpoints.
    assert out.count("Evaluated 1 episodes") == 2, out[-2000:]
    assert "success_once:" in out and "success_at_end:" in out
    assert list(run_dir.glob("events.out.tfevents.*"))
    assert (run_dir / "checkpoints" / "10.pt").exists()


@baseline
def test_maniskill_train_rgbd_on_a_converted_soft_demo(dp_dir, demos):
    with h5py.File(demos["rgb"], "r") as f:  # what the baseline reads: T+1 observations, T actions in [-1, 1]
        t = f["traj_0/actions"].shape[0]
        assert f["traj_0/obs/sensor_data/base_camera/rgb"].shape[0] == t + 1
        assert np.abs(f["traj_0/actions"][()]).max() <= 1.0
    out = _run([sys.executable, str(dp_dir / "train_rgbd.py"), *_common_flags(demos["rgb"]), "--obs-mode", "rgb",
                "--exp-name", "softvt_rgb"], demos["work"])
    assert f"Total transitions: {t}" in out
    _check_run(out, demos["work"] / "runs" / "softvt_rgb")


@baseline
def test_maniskill_train_on_a_converted_soft_demo_in_state(dp_dir, demos):
    out = _run([sys.executable, str(dp_dir / "train.py"), *_common_flags(demos["state"]),
                "--exp-name", "softvt_state"], demos["work"])
    _check_run(out, demos["work"] / "runs" / "softvt_state")


@baseline
def test_our_evaluator_scores_a_maniskill_checkpoint(dp_dir, demos, tmp_path):
    checkpoint = demos["work"] / "runs" / "softvt_rgb" / "checkpoints" / "10.pt"
    if not checkpoint.exists():
        pytest.skip("needs the checkpoint of test_maniskill_train_rgbd_on_a_converted_soft_demo")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "SOFTVT_MANISKILL_DP_DIR": str(dp_dir),
           "SOFTVT_MANISKILL_DP_CHECKPOINT": str(checkpoint)}
    proc = subprocess.run([sys.executable, "-m", "mani_skill_softvt.evaluate", "--policy",
                           "mani_skill_softvt.evaluation.maniskill_dp:ManiSkillDiffusionPolicy", "--obs-mode", "rgb", "--tasks", "3",
                           "--out", str(tmp_path)], cwd=demos["work"], env=env, capture_output=True, text=True,
                          timeout=1800)
    assert proc.returncode == 0, proc.stderr[-4000:]
    (records,) = tmp_path.glob("object_soft_id_*.jsonl")
    (record,) = [json.loads(line) for line in records.read_text().splitlines()]
    # The policy's control mode is the run's default; the episode ran to an end (20 iterations of training
    # do not solve it: an untrained policy tends to push the cube off the table) and was scored.
    assert record["obs_mode"] == "rgb" and record["control_mode"] == "pd_ee_delta_pose"
    assert record["error"] is None and record["termination"] in ("success", "dropped", "timeout")
    assert record["steps"] >= 1 and record["r_max"] >= 0.0 and record["dsr_success"] in (True, False)


# ---------------------------------------------------------------- the documented commands (fast)
def _bash_blocks(path: Path) -> list[list[str]]:
    """The commands of each ```bash block of a markdown file, continuation lines joined, comments dropped."""
    blocks, inside = [], False
    for line in path.read_text().splitlines():
        if line.strip().startswith("```"):
            inside = line.strip() == "```bash"
            if inside:
                blocks.append([])
            continue
        if inside:
            blocks[-1].append(line.split(" #")[0].rstrip() if not line.lstrip().startswith("#") else "")
    return [[c.strip() for c in "\n".join(b).replace("\\\n", " ").split("\n") if c.strip()] for b in blocks]


def _written_and_read(commands: list[str]) -> tuple[set[str], list[str]]:
    """The files a block's commands write (by the tools' naming rules) and the ones they read."""
    from mani_skill_softvt.tasks.suites import parse_env_id

    written, read, shell = set(), [], {}
    for cmd in commands:
        for k, v in shell.items():
            cmd = cmd.replace(f"${k}", v)
        words = cmd.split()
        if len(words) == 1 and "=" in words[0]:  # D=demos/...: a shell variable
            k, v = words[0].split("=", 1)
            shell[k] = v
            continue
        flag = lambda f, default=None: words[words.index(f) + 1] if f in words else default  # noqa: E731
        env = dict(w.split("=", 1) for w in words if "=" in w and w.split("=")[0].isupper())
        if "mani_skill_softvt.integrations.maniskill.motionplanning" in words:
            suite, task = parse_env_id(flag("-e"))
            written.add(f"demos/{flag('-e')}/motionplanning/task{task if task is not None else flag('--task-id')}.h5")
        elif "--traj-path" in words:  # a replay (ManiSkill's module or ours): <name>.<obs>.<control>.physx_cpu.h5
            src = flag("--traj-path")
            read.append(src)
            parts = Path(src).name.split(".")
            obs, control = (parts[1], parts[2]) if len(parts) > 2 else ("none", "pd_joint_pos")
            if "--save-traj" in words and "--upgrade-gripper" not in words:
                name = f"{parts[0]}.{flag('-o', obs)}.{flag('-c', control)}.physx_cpu.h5"
                written.add(str(Path(src).parent / name))
        elif "--demo-path" in words:  # ManiSkill's train_rgbd.py / train.py
            read.append(flag("--demo-path"))
            total, every = int(flag("--total-iters")), int(flag("--save-freq"))
            written |= {f"runs/{flag('--exp-name')}/checkpoints/{i}.pt" for i in range(0, total, every)}
        if "SOFTVT_MANISKILL_DP_CHECKPOINT" in env:
            read.append(env["SOFTVT_MANISKILL_DP_CHECKPOINT"])
    return written, read


@pytest.mark.parametrize("doc", ["README.md", "docs/maniskill.md"])
def test_the_documented_commands_read_only_what_the_commands_before_them_write(doc):
    from mani_skill_softvt.paths import REPO_DIR

    checked = 0
    for commands in _bash_blocks(REPO_DIR / doc):
        if not any("mani_skill_softvt.integrations.maniskill.motionplanning" in c for c in commands):
            continue  # the blocks that start from motion planning: every path they read, they made
        written, read = _written_and_read(commands)
        for path in read:
            assert path in written, f"{doc}: {path} is read but no command before it writes it ({sorted(written)})"
        checked += len(read)
    assert checked >= 4


def test_the_docs_give_the_evaluate_fix_the_test_applies():
    from mani_skill_softvt.paths import REPO_DIR

    assert EVALUATE_FIX in (REPO_DIR / "docs" / "maniskill.md").read_text()


FAKE_SCRIPT = '''
from dataclasses import dataclass
import torch
import tyro

@dataclass
class Args:
    obs_horizon: int = 2
    act_horizon: int = 8

class Agent(torch.nn.Module):
    """Stands in for the script's Agent: a chunk of 8 actions numbering the call, and what it saw."""
    def __init__(self, env, args):
        super().__init__()
        self.calls = torch.nn.Parameter(torch.zeros(()), requires_grad=False)
        self.seen = []
        self.act_dim = env.single_action_space.shape[0]
    def get_action(self, obs_seq):
        self.seen.append({k: v.clone() for k, v in obs_seq.items()})
        self.calls += 1
        return torch.full((1, 8, self.act_dim), float(self.calls)) + torch.arange(8.0)[None, :, None] / 10
'''


def test_a_maniskill_checkpoint_is_called_as_the_baselines_eval_calls_it(tmp_path, monkeypatch):
    """The chunk is handed out so that every prediction reads the frames of the last obs_horizon
    consecutive steps (the first frame repeated at the reset), the EMA weights loaded; no ManiSkill script needed."""
    import torch

    from mani_skill_softvt.integrations.maniskill.diffusion_policy import ManiSkillDiffusionPolicy

    (tmp_path / "train_rgbd.py").write_text(FAKE_SCRIPT)
    torch.save({"agent": {}, "ema_agent": {"calls": torch.tensor(10.0)}}, tmp_path / "7.pt")
    monkeypatch.setenv("SOFTVT_MANISKILL_DP_DIR", str(tmp_path))
    monkeypatch.setenv("SOFTVT_MANISKILL_DP_CHECKPOINT", str(tmp_path / "7.pt"))
    policy = ManiSkillDiffusionPolicy()

    def obs(t):  # the env's batch-of-one observation at step t: state and two cameras
        cam = {"rgb": torch.full((1, 4, 4, 3), t, dtype=torch.uint8)}
        return {"agent": {"qpos": torch.full((1, 2), float(t))}, "extra": {"w": torch.full((1, 1), -float(t))},
                "sensor_param": {}, "sensor_data": {"base_camera": cam, "hand_camera": cam}}

    policy.reset("instruction", seed=1)
    first = policy.act(obs(0))
    assert first.shape == (7, 7) and first[0, 0] == pytest.approx(11.0)  # the EMA weights: calls started at 10
    second = policy.act(obs(7))  # after 7 steps: the chunk's 8th action, no prediction
    assert second.shape == (1, 7) and second[0, 0] == pytest.approx(11.7)
    third = policy.act(obs(8))  # after 8 steps: a prediction from the frames of steps 7 and 8
    assert third[0, 0] == pytest.approx(12.0)
    seen = policy.agent.seen
    assert [s["state"][0, :, 0].tolist() for s in seen] == [[0.0, 0.0], [7.0, 8.0]]
    assert seen[1]["rgb"].shape == (1, 2, 4, 4, 6) and seen[1]["rgb"][0, :, 0, 0, 0].tolist() == [7, 8]
    policy.reset("instruction", seed=2)  # a new episode: the first frame repeated again
    policy.act(obs(3))
    assert seen[2]["state"][0, :, 0].tolist() == [3.0, 3.0]
