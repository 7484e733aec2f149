"""Evaluation integrity: whatever a policy does ends in a scored, recorded episode and the run goes
on; records are verified on resume and rescoring; a killed evaluator leaves no process behind."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from misbehaving_policies import BEHAVIOURS, CRUSH_TARGET_ENV, TASK, Crusher
from mani_skill_softvt.data.seeds import id_seed
from mani_skill_softvt.evaluation.metrics import summarize, tolerance_violated
from mani_skill_softvt.evaluation.policies import HoldPolicy
from mani_skill_softvt.evaluation.protocols import episodes
from mani_skill_softvt.evaluation.run import RunConfig
from mani_skill_softvt.evaluation.records import RecordIntegrityError, record_hash
from mani_skill_softvt.evaluation.runner import evaluate, run_episode
from mani_skill_softvt.fileio import CorruptLogError

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

REPO = Path(__file__).resolve().parents[1]
SPEC = "misbehaving_policies:Misbehaving"
SHORT_EPISODE = 40  # steps: enough for the crush (tets collapse from step ~34) and a quick timeout


@pytest.fixture(scope="module")
def cube_env():
    from mani_skill_softvt.evaluation.wrapper import make_env

    env = make_env("object_soft", TASK, obs_mode="state_dict", control_mode="pd_ee_pose",
                   max_episode_steps=SHORT_EPISODE)
    yield env
    env.close()


def _episode(i: int) -> dict:
    return {"suite": "object_soft", "task_id": TASK, "condition": "id", "seed": id_seed(TASK, i)}


def _target_top(env, seed: int) -> np.ndarray:
    """Where the object sits at this seed's initial state (centroid x, y and its top z)."""
    u = env.unwrapped
    env.reset(seed=seed)
    nodes = u.soft_nodes(u.target_instance)
    return np.array([*nodes[:, :2].mean(0), nodes[:, 2].max()])


def test_crushing_is_scored_as_failure_and_violation_and_the_episode_runs_on(cube_env):
    ep = _episode(BEHAVIOURS.index("crush"))
    rec = run_episode(cube_env, Crusher(_target_top(cube_env, ep["seed"])), ep)
    # The closed jaws collapse tets under them: counted, and the FEM simulates on to the step limit.
    assert rec["termination"] == "timeout" and rec["error"] is None and rec["steps"] == SHORT_EPISODE
    assert 0 < rec["collapsed_steps"] <= rec["steps"] + 1
    assert not rec["success"] and not rec["dsr_success"] and tolerance_violated(rec)
    assert rec["r_max"] > 1.0  # the closed jaws driven 10 cm below its top: far past a grasp's tolerance
    assert len(rec["deformation_trace"]) == rec["steps"] + 1
    assert rec["r_max"] == pytest.approx(max(rec["deformation_trace"]) / rec["tau_o"], rel=1e-12)
    assert rec["record_sha256"] == record_hash(rec)
    assert summarize([rec])["collapses"] == 1


def test_a_blow_up_ends_the_episode_as_sim_unstable_and_the_env_runs_on(cube_env, monkeypatch):
    """The evaluator's handling of a blow-up, provoked by lowering the speed limit of the health
    check to 5 cm/s, which the crusher's pressed nodes exceed (nothing else changes)."""
    from mani_skill_softvt.physics.fem import SoftBodyWorld

    check = SoftBodyWorld.check_health
    monkeypatch.setattr(SoftBodyWorld, "check_health", lambda self, max_speed=0.05: check(self, max_speed))
    ep = _episode(BEHAVIOURS.index("crush"))
    rec = run_episode(cube_env, Crusher(_target_top(cube_env, ep["seed"])), ep)
    assert rec["termination"] == "sim_unstable" and "speed" in rec["error"]
    assert 0 < rec["steps"] < SHORT_EPISODE and len(rec["deformation_trace"]) == rec["steps"] + 1
    assert not rec["success"] and not rec["dsr_success"] and tolerance_violated(rec)
    assert rec["r_max"] == pytest.approx(max(rec["deformation_trace"]) / rec["tau_o"], rel=1e-12)
    monkeypatch.undo()
    # The same env resets cleanly after a blow-up: holding still until the step limit is a timeout.
    hold = run_episode(cube_env, HoldPolicy(), _episode(0))
    assert hold["termination"] == "timeout" and hold["steps"] == SHORT_EPISODE and not hold["success"]
    assert hold["r_max"] < 0.1 and hold["collapsed_steps"] == 0  # nothing touched the object: only settling


@pytest.mark.slow  # in CI's slow pass: the crushing episode alone is about 2 min of FEM
def test_every_misbehaviour_ends_in_a_record_and_the_run_goes_on(cube_env, tmp_path, monkeypatch):
    """One evaluation run through the runner's worker, one misbehaviour an episode. The crushing
    episode simulates on to the protocol's step limit, so the default run keeps the crushing and
    blow-up tests above (the same ``run_episode`` on a 40-step env) and the served policy's failures
    (tests/test_remote_policy.py)."""
    assert BEHAVIOURS[-1] == "crush"
    crush_seed = id_seed(TASK, BEHAVIOURS.index("crush"))
    monkeypatch.setenv(CRUSH_TARGET_ENV, ",".join(repr(float(v)) for v in _target_top(cube_env, crush_seed)))
    eps = episodes("object_soft", "id", tasks=[TASK], per_task=len(BEHAVIOURS))
    out = tmp_path / "misbehaving.jsonl"
    records = evaluate(RunConfig.resolve(SPEC), out, eps)
    assert [r["seed"] for r in records] == [e["seed"] for e in eps]
    got = dict(zip(BEHAVIOURS, records))
    expected = {"raise_in_act": ("policy_error", "ZeroDivisionError in policy.act(): deliberate failure in act"),
                "nan": ("policy_error", "NaN"), "wrong_shape": ("policy_error", "shape (6,)"),
                "strings": ("policy_error", "must be numbers"), "kill_own_process": ("worker_died", "SIGKILL"),
                "raise_in_reset": ("policy_error", "KeyError in policy.reset()"), "crush": ("timeout", None)}
    for b in BEHAVIOURS:
        termination, message = expected[b]
        r = got[b]
        assert r["termination"] == termination and (message is None) == (r["error"] is None), (b, r["termination"])
        assert message is None or message in r["error"], (b, r["error"])
        assert not r["success"] and not r["dsr_success"]
        assert (r["policy"], r["obs_mode"], r["control_mode"]) == (SPEC, "state", "pd_ee_pose")  # the env's default mode
        assert r["record_sha256"] == record_hash(r)
    # Policies that behaved for two single-step chunks first: exactly two steps were executed.
    assert got["raise_in_act"]["steps"] == got["nan"]["steps"] == 2 and got["raise_in_reset"]["steps"] == 0
    assert got["kill_own_process"]["r_max"] is None  # nothing of a dead worker's episode survives
    s = summarize(records)
    assert s["terminations"] == {"policy_error": 5, "worker_died": 1, "timeout": 1}
    assert s["tolerance_violations"] == s["collapses"] == 1
    assert got["crush"]["collapsed_steps"] > 0
    assert s["tsr"] == s["dsr"] == 0.0

    # Resume: nothing re-runs; every line is verified.
    ticks = []
    assert evaluate(RunConfig.resolve(SPEC), out, eps, progress=ticks.append) == records and ticks == [len(eps)]
    # Another control mode is another run: its records are not reused, and the first run's stay.
    other = evaluate(RunConfig.resolve(SPEC, control_mode="pd_ee_pose_binary"), out, eps[5:6])
    assert other[0]["control_mode"] == "pd_ee_pose_binary" and other[0]["termination"] == "policy_error"
    assert evaluate(RunConfig.resolve(SPEC), out, eps) == records

    lines = out.read_text().splitlines()
    tampered = json.loads(lines[1])
    tampered["r_max"] = 0.0
    for bad, error, where in ((json.dumps(tampered), RecordIntegrityError, f"{out}:2:"),
                              ('{"suite": "object_so', CorruptLogError, f"{out}:2:")):
        out.write_text("\n".join([lines[0], bad, *lines[2:]]) + "\n")
        with pytest.raises(error, match=where):
            evaluate(RunConfig.resolve(SPEC), out, eps)
        from mani_skill_softvt.cli.evaluate import main

        # The command says it in one line naming the file, the line and what to do, not a traceback.
        with pytest.raises(SystemExit, match=where) as exit_:
            main(["--rescore", str(out), "--percentile", "80", "--out", str(tmp_path)])
        assert "\n" not in str(exit_.value) and ("remove the line" in str(exit_.value) or "corrupt" in str(exit_.value))
    # A torn last line (killed writer) is still recovered: the records before it stand.
    out.write_text("\n".join(lines) + '\n{"suite": "obj')
    assert evaluate(RunConfig.resolve(SPEC), out, eps) == records


def _descendants(pid: int) -> set[int]:
    children = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_kill_9_of_the_evaluator_leaves_no_process_behind(tmp_path):
    # 20 hold episodes: minutes of work, so the worker is still busy when the evaluator is killed.
    proc = subprocess.Popen([sys.executable, "-m", "mani_skill_softvt.evaluate", "--policy", "hold", "--tasks", "3",
                             "--episodes-per-task", "20", "--out", str(tmp_path)], cwd=REPO,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        workers = set()
        while not workers and time.monotonic() < deadline:
            time.sleep(0.5)
            workers = {p for p in _descendants(proc.pid)
                       if b"spawn_main" in Path(f"/proc/{p}/cmdline").read_bytes()}
        assert workers, "the evaluator started no worker"
        time.sleep(15)  # the worker has imported the package and is building or running the env
        family = _descendants(proc.pid)
        assert workers <= family, "the worker ended before the kill: give it more work"
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + 20
        while any(_alive(p) for p in family) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not [p for p in family if _alive(p)], "processes outlived the killed evaluator"
    finally:
        if proc.poll() is None:
            proc.kill()


def test_records_of_another_tactile_model_are_another_run(tmp_path):
    # Frames of another tactile model are other observations: resuming never pools them. Records
    # from before the version was kept count as model 1.
    from mani_skill_softvt.evaluation.policies import PolicySource
    from mani_skill_softvt.evaluation.runner import run_records
    from mani_skill_softvt.fileio import append_jsonl
    from mani_skill_softvt.tasks.suites import SUITES

    MODEL_VERSION = SUITES["object_soft"].tactile_model

    out = tmp_path / "records.jsonl"
    base = {"suite": "object_soft", "condition": "id", "policy": "p.pt", "obs_mode": "rgb+tactile",
            "control_mode": "pd_ee_pose", "termination": "timeout"}
    for task, extra in ((0, {}), (1, {"tactile_model": MODEL_VERSION})):
        rec = {**base, "task_id": task, "seed": task, **extra}
        append_jsonl(out, {**rec, "record_sha256": record_hash(rec)})
    run = RunConfig(PolicySource("p.pt", "diffusion_policy"), "rgb+tactile", "pd_ee_pose", None)
    got = run_records(out, run)
    assert MODEL_VERSION > 1 and [r["task_id"] for r in got.values()] == [1]


class ClaimsPrivilege(HoldPolicy):
    """A user policy that declares itself privileged to get the env handed over."""

    privileged = True
    env = None

    def bind(self, env):
        self.env = env


def test_a_user_policy_cannot_claim_the_privilege_of_the_builtin_experts(cube_env):
    policy = ClaimsPrivilege()
    rec = run_episode(cube_env, policy, _episode(0))
    assert policy.env is None and not rec["receipt"]["privileged"]
    assert rec["termination"] in ("timeout", "success", "dropped") and rec["steps"] > 0


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_the_evaluator_renders_the_cameras_at_the_size_a_policy_asks_for(tmp_path):
    """A policy trained on small images (``camera_size``) sees its cameras rendered at that size,
    and its record says so; other policies' records keep the native 224x224."""
    eps = episodes("object_soft", "id", tasks=[TASK], per_task=1)
    small = RunConfig.resolve("misbehaving_policies:SmallCameras", obs_mode="rgb")
    (rec,) = evaluate(small, tmp_path / "small.jsonl", eps)
    assert rec["termination"] == "policy_error" and "NaN" in rec["error"], rec["error"]  # not "cameras seen at"
    assert rec["camera_size"] == [24, 32] and rec["steps"] == 0
    # Another camera size is another run; asking the policy for one it was not trained on is refused.
    from mani_skill_softvt.evaluation.records import migrate_record
    from mani_skill_softvt.evaluation.runner import run_records

    from dataclasses import replace

    assert small.camera_size == (24, 32) and run_records(tmp_path / "small.jsonl", small)
    assert not run_records(tmp_path / "small.jsonl", replace(small, camera_size=None))
    with pytest.raises(ValueError, match="trained on 24x32 cameras; evaluate it at that size"):
        RunConfig.resolve("misbehaving_policies:SmallCameras", obs_mode="rgb", camera_size=(84, 84))
    # Records from before the size was kept had the native cameras; state modes have none.
    old = {"obs_mode": "rgb", "success": True, "r_max": 0.5}
    assert migrate_record(old)["camera_size"] == [224, 224]
    assert migrate_record(dict(old, obs_mode="state_dict"))["camera_size"] is None
