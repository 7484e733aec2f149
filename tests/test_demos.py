"""Expert demonstrations: ManiSkill trajectory format, exact replay from stored states, QC."""

import json

import gymnasium as gym
import h5py
import numpy as np
import pytest
import torch

import mani_skill_softvt  # noqa: F401
from mani_skill_softvt.demonstrations.generate import generate
from mani_skill_softvt.demonstrations.stats import format_stats, stats
from mani_skill_softvt.data.trajectory import read_episode, screen


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("demos")
    report = generate("object_soft", [3], 1, out)
    return out, report


def test_generation_writes_maniskill_trajectories_with_evaluator_stream(dataset):
    out, report = dataset
    assert report["tasks"][0]["accepted"] == 1, report
    meta = json.loads((out / "object_soft" / "task3.json").read_text())
    assert meta["source_type"] == "motionplanning" and meta["env_info"]["env_id"] == "mani_skill_softvt:SoftVTObjectSoft-Task3-v1"
    ep_meta = meta["episodes"][0]
    assert ep_meta["instruction"].startswith("Pick up the soft cream-colored cube")
    with h5py.File(out / "object_soft" / "task3.h5", "r") as f:
        traj = f["traj_0"]
        t = traj["actions"].shape[0]
        assert traj["actions_binary"].shape == (t, 7) and set(np.unique(traj["actions_binary"][:, 6])) <= {0.0, 1.0}
        assert traj["env_states/soft"].shape[0] == t + 1 and traj["evaluator/nodes"].shape[0] == t + 1
        assert traj["evaluator/collapsed_tets"].shape == (t + 1,) and not traj["evaluator/collapsed_tets"][()].any()
        assert traj["success"][-1] and ep_meta["elapsed_steps"] == t
    manifest = json.loads((out / "object_soft" / "manifest.json").read_text())
    assert manifest["train_seeds"]["3"][1] < manifest["id_eval_seeds"]["3"][0]
    from mani_skill_softvt.physics.config import physics_signature

    assert manifest["physics"] == physics_signature()


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_a_round_that_records_nothing_keeps_the_merged_file_and_a_newer_episode_is_merged_again(dataset):
    import os

    out, _ = dataset
    merged = out / "object_soft" / "task3.h5"
    episode = next((out / "object_soft" / "task3").glob("ep_*.h5"))
    before = merged.stat().st_mtime_ns, merged.read_bytes()
    generate("object_soft", [3], 1, out)  # every seed recorded: nothing new, nothing merged
    assert merged.stat().st_mtime_ns == before[0]
    from mani_skill_softvt.data.demo_set import DemoSet

    assert DemoSet(out, "object_soft").accepted_listed(3) == 1 and DemoSet(out, "object_soft").accepted_listed(2) == 0
    os.utime(episode, ns=(before[0] + 10**9, before[0] + 10**9))  # as if recorded again after the merge
    generate("object_soft", [3], 1, out)
    assert merged.stat().st_mtime_ns > before[0] and merged.read_bytes() == before[1]
    from mani_skill_softvt.demonstrations.generate import merged_is_current

    seed = json.loads(merged.with_suffix(".json").read_text())["episodes"][0]["episode_seed"]
    assert merged_is_current(merged, merged.with_suffix(".json"), [seed], [episode])
    assert not merged_is_current(merged, merged.with_suffix(".json"), [seed + 1], [episode])  # another episode


def test_resuming_demos_recorded_under_other_physics_is_refused(dataset, tmp_path):
    out, _ = dataset
    manifest = json.loads((out / "object_soft" / "manifest.json").read_text())
    manifest["physics"]["FRICTION_EPSILON"] *= 10
    (tmp_path / "object_soft").mkdir()
    (tmp_path / "object_soft" / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ValueError, match="manifest.json.*other physics.*FRICTION_EPSILON"):
        generate("object_soft", [3], 1, tmp_path)
    assert json.loads((tmp_path / "object_soft" / "manifest.json").read_text()) == manifest  # left as it was


@pytest.mark.slow  # about a minute of physics or training on 2 cores; CI runs it (-m slow)
def test_a_fresh_checkout_records_the_accepted_episodes_its_committed_qc_log_lists(tmp_path):
    """The QC logs are committed and the episode files are not: generate records an accepted
    episode again where its file is missing, appends the new verdict and merges the task."""
    from mani_skill_softvt.data.demo_set import DemoSet

    generate("object_rigid", [3], 1, tmp_path)
    demo_set = DemoSet(tmp_path, "object_rigid")
    (first,) = demo_set.read_qc(3)
    assert first["accepted"], first
    episode = demo_set.episode_file(3, first["seed"])
    with h5py.File(episode, "r") as f:
        recorded = f["traj_0/env_states/actors"]
        recorded = {k: recorded[k][()] for k in recorded}
    episode.unlink()
    episode.with_suffix(".json").unlink()
    demo_set.trajectory(3).unlink()
    report = generate("object_rigid", [3], 1, tmp_path)
    assert report["tasks"][0]["accepted"] == 1 and demo_set.trajectory(3).exists()
    again = demo_set.read_qc(3)
    assert len(again) == 2 and again[1]["seed"] == first["seed"] and again[1]["r_max"] == first["r_max"]
    with h5py.File(episode, "r") as f:  # same machine, same seed: the same episode, bit for bit
        assert all(np.array_equal(f[f"traj_0/env_states/actors/{k}"][()], v) for k, v in recorded.items())
    generate("object_rigid", [3], 1, tmp_path)  # now complete: nothing recorded again
    assert len(demo_set.read_qc(3)) == 2
    summary = stats("object_rigid", tmp_path)  # one episode, however often it was logged
    assert (summary["generated"], summary["accepted"]) == (1, 1)
    assert summary["rerecorded"] == {"repeats": 1, "same_verdict": 1, "same_steps": 1, "r_max_equal": 1, "r_max_nan_once": 0,
                                     "r_max_largest_difference": 0.0, "r_max_largest_difference_seed": None}
    assert "recorded again: 1; first verdict kept 1/1, step count 1/1, R_max the same bits 1/1\n" in \
        format_stats(summary) + "\n"


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_screening_grows_the_qc_log_without_recording_again_what_it_lists(tmp_path):
    """generate --screen-only (a set grown over sessions on machines that keep nothing): an accepted
    seed the committed log lists is not recorded again, the next seed is drawn and recorded, nothing
    is merged, and the stats count the listed episode as accepted but not on this machine."""
    from mani_skill_softvt.data.demo_set import DemoSet
    from mani_skill_softvt.data.seeds import train_seed
    from mani_skill_softvt.fileio import append_jsonl

    demo_set = DemoSet(tmp_path, "object_rigid")
    first = train_seed(3, 0)
    listed = {"seed": first, "planner": "mplib", "accepted": True, "problems": [], "steps": 100, "r_max": 0.5,
              "wall_s": 1.0}
    append_jsonl(demo_set.qc_log(3), listed)
    (row,) = generate("object_rigid", [3], 2, tmp_path, accepted=2, screen_only=True)["tasks"]
    assert (row["generated"], row["accepted"]) == (2, 2), row
    assert [q["seed"] for q in demo_set.read_qc(3)] == [first, first + 1]  # the listed seed: not recorded again
    assert not demo_set.episode_file(3, first).exists() and demo_set.episode_file(3, first + 1).exists()
    assert not demo_set.trajectory(3).exists()  # a subset is never merged as if it were the set
    summary = stats("object_rigid", tmp_path)
    assert (summary["accepted"], summary["tasks"][0]["recorded_here"], summary["unreadable_files"]) == (2, 1, [])
    assert "on this machine: 1 of the 2 accepted episodes" in format_stats(summary)


def test_a_committed_accepted_demo_is_recorded_again_as_its_qc_log_says(tmp_path):
    """Under the pinned numerics a seed's demo is the same episode on any machine: the first
    accepted seed of the committed Spatial-Rigid task 3 (recorded under the pins in an earlier
    session) is recorded again with the step count and the R_max (to the bit)
    its committed QC log line holds; the expert's settle (below) left it as it was. (The Object sets
    predate the pins: their manifests name no numerics, and their bits are their machine's.)"""
    from mani_skill_softvt.data.demo_set import DemoSet
    from mani_skill_softvt.demonstrations.generate import record_demo
    from mani_skill_softvt.evaluation.wrapper import make_env
    from mani_skill_softvt.paths import REPO_DIR

    demos = DemoSet(REPO_DIR / "demo-data", "spatial_rigid")
    assert json.loads(demos.manifest.read_text())["numerics"] == "x86-64-v3"
    line = next(q for q in demos.verdicts(3) if q["accepted"])
    env = make_env("spatial_rigid", 3, obs_mode="none", control_mode="pd_ee_pose")
    try:
        problems, ep = record_demo(env, line["seed"], tmp_path / "ep.h5", line["planner"])
    finally:
        env.close()
    assert problems == [] and len(ep["actions"]) == line["steps"]
    assert float(np.max(ep["evaluator"]["deformation_ratio"])) == line["r_max"]


@pytest.mark.slow  # a Spatial-Soft demo: about a minute of physics; CI runs it (-m slow)
def test_a_plan_that_ends_with_the_object_still_moving_holds_until_it_rests():
    """Spatial-Soft task 9's pastry rocks on the plate after the release on some seeds: its first
    training seed's plan ends with the object in the target but not at rest. The expert holds its
    last pose until the object rests (at most SETTLE_STEPS ticks), so the demo ends in success
    instead of being rejected; success then ends the episode, as it does in evaluation."""
    from mani_skill_softvt.data.seeds import train_seed
    from mani_skill_softvt.demonstrations.generate import record_demo
    from mani_skill_softvt.evaluation.wrapper import make_env
    from mani_skill_softvt.expert.solution import SETTLE_STEPS

    import tempfile
    from pathlib import Path

    env = make_env("spatial_soft", 9, obs_mode="none", control_mode="pd_ee_pose")
    try:
        with tempfile.TemporaryDirectory() as d:
            problems, ep = record_demo(env, train_seed(9, 0), Path(d) / "ep.h5", "mplib")
    finally:
        env.close()
    success = np.asarray(ep["success"], dtype=bool)
    assert problems == [] and success[-1] and not success[-2], (problems, success[-5:])
    plan_end = int(np.flatnonzero(~success[:-1])[-1]) + 1  # the settle ran from the plan's end at most
    assert len(success) - plan_end <= SETTLE_STEPS


@pytest.mark.slow  # about a minute of physics or training on 2 cores; CI runs it (-m slow)
def test_accepted_mode_draws_seeds_in_order_until_enough_demos_are_accepted(tmp_path, capsys):
    """A task whose expert fails on a seed still ends with the demos asked for: the rejected seed
    (logged) is skipped, the next seed is drawn, and drawing stops at the count asked."""
    from mani_skill_softvt.data.demo_set import DemoSet
    from mani_skill_softvt.data.seeds import train_seed
    from mani_skill_softvt.cli.demos import main
    from mani_skill_softvt.demonstrations.generate import accepted_demos_expected
    from mani_skill_softvt.fileio import append_jsonl

    demo_set = DemoSet(tmp_path, "object_rigid")
    first = train_seed(3, 0)
    append_jsonl(demo_set.qc_log(3), {"seed": first, "planner": "mplib", "accepted": False,
                                       "problems": ["not successful at the last step"], "steps": 150, "r_max": 0.5,
                                       "wall_s": 10.0})
    report = generate("object_rigid", [3], 3, tmp_path, accepted=1)
    (row,) = report["tasks"]
    assert (row["generated"], row["accepted"], row["train_seeds"]) == (2, 1, [first, first + 1]), row
    assert [q["seed"] for q in demo_set.verdicts(3)] == [first, first + 1]  # seed 2 was never drawn
    manifest = json.loads(demo_set.manifest.read_text())
    assert manifest["train_seeds"]["3"] == [first, first + 1]
    with h5py.File(demo_set.trajectory(3), "r") as f:
        assert list(f.keys()) == ["traj_0"] and f["traj_0"].attrs["seed"] == first + 1
    # The progress bar's total: the demos asked for, or the accepted ones the log lists if more.
    assert accepted_demos_expected(demo_set, 3, 3, 1) == 1 and accepted_demos_expected(demo_set, 3, 3, 3) == 3
    # Seeds generated before are kept: asking for fewer never shrinks the set (nor its renderings).
    append_jsonl(demo_set.qc_log(3), {**demo_set.verdicts(3)[1], "seed": first + 2})  # as if generated
    import shutil

    shutil.copy(demo_set.episode_file(3, first + 1), demo_set.episode_file(3, first + 2))
    shutil.copy(demo_set.episode_file(3, first + 1).with_suffix(".json"),
                demo_set.episode_file(3, first + 2).with_suffix(".json"))
    assert accepted_demos_expected(demo_set, 3, 3, 1) == 2  # the log lists two: both are held, both counted
    (row,) = generate("object_rigid", [3], 3, tmp_path, accepted=1)["tasks"]
    assert (row["generated"], row["accepted"]) == (3, 2) and len(demo_set.verdicts(3)) == 3
    with pytest.raises(SystemExit):
        main(["generate", "--suite", "object_rigid", "--tasks", "3", "--num", "2", "--accepted", "3", "--out",
              str(tmp_path)])
    assert "--num caps the seeds" in capsys.readouterr().err


def test_stored_states_replay_the_actions_bit_for_bit(dataset):
    out, _ = dataset
    ep = read_episode(next((out / "object_soft" / "task3").glob("ep_*.h5")))
    env = gym.make("SoftVTObjectSoft-v1", task_id=3, obs_mode="none")
    env.reset(seed=int(ep["seed"]))
    u = env.unwrapped
    for t in range(15):
        env.step(ep["actions"][t])
    np.testing.assert_array_equal(u.get_state_dict()["soft"][0].numpy(), ep["env_states"]["soft"][15])
    # And restoring a stored state, then stepping, reproduces the next stored state.
    state = {"soft": torch.from_numpy(ep["env_states"]["soft"][20][None])}
    full = u.get_state_dict()
    for group in ("actors", "articulations"):
        for name in full[group]:
            state.setdefault(group, {})[name] = torch.from_numpy(ep["env_states"][f"{group}/{name}"][20][None])
    u.set_state_dict(state)
    env.step(ep["actions"][20])
    np.testing.assert_array_equal(u.get_state_dict()["soft"][0].numpy(), ep["env_states"]["soft"][21])
    env.close()


def test_screening_rejects_broken_episodes(dataset):
    out, _ = dataset
    ep = read_episode(next((out / "object_soft" / "task3").glob("ep_*.h5")))
    assert screen(ep) == []
    bad = dict(ep, evaluator=dict(ep["evaluator"]))
    bad["evaluator"]["deformation_ratio"] = ep["evaluator"]["deformation_ratio"] * 0 + 1.5
    assert any("R_max" in p for p in screen(bad))
    bad = dict(ep, evaluator=dict(ep["evaluator"]))
    bad["evaluator"]["collapsed_tets"] = np.where(np.arange(len(ep["evaluator"]["collapsed_tets"])) == 40, 3, 0)
    assert any("collapsed" in p for p in screen(bad))  # within tolerance, yet a tet collapsed
    bad = dict(ep, success=np.zeros_like(ep["success"]))
    assert any("not successful" in p for p in screen(bad))
    bad = dict(ep, actions=ep["actions"][:-1])
    assert any("steps" in p for p in screen(bad))


def test_stats(dataset, tmp_path):
    out, _ = dataset
    s = stats("object_soft", out)
    assert s["tasks"][0]["accepted"] == 1 and s["r_max_median"] < 1.0 and s["tasks"][0]["rejected"] == {}
    assert (out / "object_soft" / "r_max_hist.png").exists()
    assert json.loads((out / "object_soft" / "stats.json").read_text()) == s
    rows = [line.split() for line in format_stats(s).splitlines()]
    task_row = next(r for r in rows if r[:1] == ["3"])  # one row per task with demos
    assert task_row[1] == "1/1" and float(task_row[2]) == pytest.approx(s["r_max_median"], abs=5e-4)
    with pytest.raises(FileNotFoundError, match="run 'python -m mani_skill_softvt.demos generate"):
        stats("object_soft", tmp_path)


def test_episodes_recorded_again_are_compared_with_their_first_verdict():
    from mani_skill_softvt.data.demo_set import latest_verdicts
    from mani_skill_softvt.demonstrations.stats import rerecord_agreement

    def line(seed, accepted=True, steps=150, r_max=0.5):
        return {"seed": seed, "accepted": accepted, "steps": steps, "r_max": r_max, "problems": []}

    log = [line(1), line(2, r_max=0.25), line(3, accepted=False, steps=300), line(4),  # the committed log
           line(1), line(2, r_max=0.25 + 2**-40), line(4, steps=151, r_max=0.7),      # this machine's
           line(1, r_max=0.5 + 1e-3)]                                                   # a third machine's
    assert rerecord_agreement(log) == {"repeats": 4, "same_verdict": 4, "same_steps": 3, "r_max_equal": 1,
                                       "r_max_nan_once": 0, "r_max_largest_difference": pytest.approx(0.2),
                                       "r_max_largest_difference_seed": 4}
    assert rerecord_agreement(log[:4])["repeats"] == 0
    # Each seed's verdict is its latest line, in the order the seeds were first logged.
    assert [(q["seed"], q["r_max"]) for q in latest_verdicts(log)] == [(1, 0.5 + 1e-3), (2, 0.25 + 2**-40),
                                                                     (3, 0.5), (4, 0.7)]
    nan = float("nan")  # a diverged episode: NaN twice is the same outcome, once is counted on its own
    again = rerecord_agreement([line(5, r_max=nan), line(6), line(5, r_max=nan), line(6, r_max=nan)])
    assert again["r_max_equal"] == 1 and again["r_max_nan_once"] == 1
    assert again["r_max_largest_difference"] == 0.0 and again["r_max_largest_difference_seed"] is None
    json.dumps(again, allow_nan=False)  # stats.json stays standard JSON (no Infinity)


def test_replay_renders_observations_on_the_same_timeline(dataset, tmp_path):
    from mani_skill_softvt.demonstrations.render import render_observations

    out, _ = dataset
    src = out / "object_soft" / "task3.h5"
    dst = tmp_path / "obs.h5"
    assert render_observations(src, dst, "object_soft", 3, "state_dict") == (1, 1)
    with h5py.File(src, "r") as f, h5py.File(dst, "r") as g:
        t = f["traj_0/actions"].shape[0]
        qpos = g["traj_0/obs/agent/qpos"][()]
        assert qpos.shape[0] == t + 1  # one observation per stored state, no resampling
        robot_state = f["traj_0/env_states/articulations/panda_softvt"][()]
        np.testing.assert_allclose(qpos, robot_state[:, 13:13 + 9], atol=1e-6)
        names = []
        g.visit(names.append)
        assert not any("evaluator" in n or "soft" in n.split("/")[-1] for n in names)


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_a_rigid_twins_touch_renders_from_its_stored_states_as_the_live_episode_showed_it(tmp_path):
    """PhysX computes contacts only when it steps, so a restored state has none: the twins' contact
    wrenches are part of the env state, and a rendering shows the pinch the live episode showed.
    The committed rigid sample, rendered from its states and stepped live from its seed: the same
    pressed frames, each pad's indentation within the observation's 1 um rounding (restored link
    poses can differ from the stepped ones in their last bits), and a patch exactly while the
    recorded pad force holds the twin."""
    from mani_skill_softvt.demonstrations.render import render_observations
    from mani_skill_softvt.evaluation.wrapper import make_env
    from mani_skill_softvt.contracts.observations import flatten_batch
    from mani_skill_softvt.paths import REPO_DIR

    src, size = REPO_DIR / "demo-data" / "sample" / "object_rigid" / "task3.h5", (16, 16)
    render_observations(src, tmp_path / "touch.h5", "object_rigid", 3, "rgb+tactile", camera_size=size)
    episode = read_episode(src)
    env = make_env("object_rigid", 3, dsr=False, obs_mode="rgb+tactile", camera_size=size, control_mode="pd_ee_pose")
    try:
        seed = json.loads(src.with_suffix(".json").read_text())["episodes"][0]["episode_seed"]
        live = [flatten_batch(env.reset(seed=seed)[0])]
        live += [flatten_batch(env.step(a)[0]) for a in episode["actions"]]
    finally:
        env.close()
    force = np.concatenate([[[0.0, 0.0]], episode["evaluator"]["pad_force"]])  # N, per observation
    with h5py.File(tmp_path / "touch.h5", "r") as f:
        for i, side in enumerate(("left", "right")):
            rendered = f[f"traj_0/obs/tactile/{side}/depth"][()].astype(int)
            stepped = np.stack([o[f"tactile/{side}/depth"] for o in live]).astype(int)
            assert np.abs(rendered - stepped).max() <= 1, side
            pressed = rendered.reshape(len(rendered), -1).max(1) > 0
            assert pressed.sum() > 50 and np.array_equal(pressed, force[:, i] > 0.0), side
            markers = f[f"traj_0/obs/tactile/{side}/marker_current"][()]
            np.testing.assert_allclose(markers, np.stack([o[f"tactile/{side}/marker_current"] for o in live]), atol=1e-3)


def test_a_rigid_trajectory_recorded_without_its_contact_state_is_refused_for_touch(tmp_path):
    """An older rigid recording would render its pinch as a blank gel: refused, naming the file and the fix."""
    import shutil

    from mani_skill_softvt.demonstrations.render import render_observations
    from mani_skill_softvt.paths import REPO_DIR

    src = tmp_path / "task3.h5"
    shutil.copy(REPO_DIR / "demo-data" / "sample" / "object_rigid" / "task3.h5", src)
    with h5py.File(src, "a") as f:
        del f["traj_0/env_states/contact_wrenches"]
    with pytest.raises(ValueError, match=f"{src}: seed 300000 .*record the demos again"):
        render_observations(src, tmp_path / "touch.h5", "object_rigid", 3, "rgb+tactile", camera_size=(16, 16))
    assert render_observations(src, tmp_path / "state.h5", "object_rigid", 3, "state_dict") == (1, 1)  # no touch: fine


@pytest.mark.slow  # two renderings of the demo; the native size is checked by default
def test_render_at_a_camera_size_shows_the_same_views_with_fewer_pixels(dataset, tmp_path):
    """``render --camera-size`` renders both cameras at that size (ManiSkill's sensor_configs, kept
    in the json for its tools): the same views as the native 224x224 rendering shrunk to that
    size, up to the sampling of the raster (far less than the robot's motion changes a view)."""
    import shutil

    from mani_skill_softvt.data.demo_set import DemoSet
    from mani_skill_softvt.data.images import resize_image
    from mani_skill_softvt.cli.demos import main

    out, _ = dataset
    shutil.copytree(out / "object_soft", tmp_path / "object_soft")
    ds = DemoSet(tmp_path, "object_soft")
    main(["render", "--tasks", "3", "--obs-mode", "rgb", "--camera-size", "56x56", "--out", str(tmp_path)])
    main(["render", "--tasks", "3", "--obs-mode", "rgb", "--out", str(tmp_path)])
    sized_h5 = ds.rendered(3, "rgb", (56, 56))
    assert sized_h5.name == "task3_rgb_56x56.h5" and ds.rendered(3, "rgb").exists()
    meta = json.loads(sized_h5.with_suffix(".json").read_text())
    assert meta["env_info"]["env_kwargs"]["sensor_configs"] == {"width": 56, "height": 56}
    with h5py.File(sized_h5, "r") as f, h5py.File(ds.rendered(3, "rgb"), "r") as g:
        for cam in ("base_camera", "hand_camera"):
            small = f[f"traj_0/obs/sensor_data/{cam}/rgb"][()].astype(np.float32)
            native = g[f"traj_0/obs/sensor_data/{cam}/rgb"][()]
            assert small.shape == (native.shape[0], 56, 56, 3) and native.shape[1:3] == (224, 224)
            shrunk = np.stack([resize_image(im, (56, 56)) for im in native]).astype(np.float32)
            raster = np.abs(small - shrunk).mean(axis=(1, 2, 3))
            motion = np.abs(shrunk[-1] - shrunk[0]).mean()
            assert raster.max() < 0.25 * motion, (cam, raster.max(), motion)


def test_truncated_demo_files_are_named(dataset, tmp_path, capsys):
    import shutil

    from mani_skill_softvt.data.demo_set import DemoSet
    from mani_skill_softvt.data.trajectory import CorruptDataError
    from mani_skill_softvt.cli.demos import main

    src, _ = dataset
    out = tmp_path / "demos"
    shutil.copytree(src, out)
    demo_set = DemoSet(out, "object_soft")
    seed = demo_set.read_qc(3)[0]["seed"]
    episode, trajectory = demo_set.episode_file(3, seed), demo_set.trajectory(3)
    rendering = demo_set.rendered(3, "rgb+tactile")
    for path, source in ((episode, episode), (trajectory, trajectory), (rendering, trajectory)):
        data = source.read_bytes()
        path.write_bytes(data[: len(data) // 2])  # a writer killed half way (or a full disk)
    s = stats("object_soft", out)
    assert len(s["unreadable_files"]) == 3
    for path, problem in zip((episode, trajectory, rendering), s["unreadable_files"]):
        assert problem.startswith(str(path)) and "truncated" in problem
    with pytest.raises(SystemExit) as e:
        main(["stats", "--out", str(out)])
    assert e.value.code == 1 and str(trajectory) in capsys.readouterr().out
    with pytest.raises(CorruptDataError, match=str(episode)):
        read_episode(episode)
    for argv in (["render", "--tasks", "3", "--out", str(out)],
                 ["export-lerobot", "--tasks", "3", "--out", str(out), "--lerobot-out", str(tmp_path / "lr")]):
        with pytest.raises(SystemExit):
            main(argv)
        assert f"{trajectory} is not a readable HDF5 file" in capsys.readouterr().err


def _stored_episodes(path, episodes):
    """A trajectory file of ``episodes`` = [(seed, length)]: actions and env states that differ per seed."""
    with h5py.File(path, "w") as f:
        for i, (seed, t) in enumerate(episodes):
            g = f.create_group(f"traj_{i}")
            g.attrs["seed"] = seed
            g["actions"] = np.full((t, 7), seed, np.float32)
            g["env_states/actors/cube"] = np.arange((t + 1) * 13, dtype=np.float32).reshape(t + 1, 13) + seed


def test_render_resumes_only_over_a_complete_current_rendering(tmp_path):
    from mani_skill_softvt.data.trajectory import episode_digest
    from mani_skill_softvt.demonstrations.render import rendering_is_current

    traj, rendered = tmp_path / "task0.h5", tmp_path / "task0_rgb_tactile.h5"
    _stored_episodes(traj, [(7, 3), (8, 4)])
    assert not rendering_is_current(traj, rendered)
    with h5py.File(traj, "r") as a, h5py.File(rendered, "w") as b:
        b.create_group("traj_0/obs").parent.attrs["states_sha256"] = episode_digest(a["traj_0"])
        digest_1 = episode_digest(a["traj_1"])
    assert not rendering_is_current(traj, rendered)  # an episode is missing
    with h5py.File(rendered, "a") as f:
        f.create_group("traj_1/obs").parent.attrs["states_sha256"] = digest_1
    assert rendering_is_current(traj, rendered)
    assert not rendering_is_current(traj, rendered, needed=("tactile/left/depth",))  # from an older version
    assert not rendering_is_current(traj, rendered, tactile_model=2)  # no version kept: model 1
    with h5py.File(rendered, "a") as f:
        for k in f:
            f[k].attrs["tactile_model"] = 2
    assert rendering_is_current(traj, rendered, tactile_model=2)
    assert not rendering_is_current(traj, rendered, tactile_model=3)
    _stored_episodes(traj, [(7, 3), (9, 4)])  # the second episode was recorded again: other states
    assert not rendering_is_current(traj, rendered)


def test_a_grown_demo_set_renders_only_its_new_episodes(tmp_path):
    """Episodes an earlier rendering holds from the same states are kept as they are; new or changed
    ones are rendered; the file follows the trajectory's episode order."""
    from mani_skill_softvt.data.trajectory import write_rendering

    traj, out = tmp_path / "task0.h5", tmp_path / "task0_state.h5"
    calls = []

    def observe(seed, states):
        calls.append(seed)
        return [{"agent/qpos": row[:9] * 2} for row in states["actors/cube"]]

    _stored_episodes(traj, [(7, 3), (8, 4)])
    assert write_rendering(traj, out, "state", observe) == (2, 2) and calls == [7, 8]
    with h5py.File(out, "r") as f:
        first = f["traj_0/obs/agent/qpos"][()]
    _stored_episodes(traj, [(5, 2), (7, 3), (8, 5)])  # a new seed first; seed 8 recorded again, longer
    assert write_rendering(traj, out, "state", observe) == (3, 2) and calls == [7, 8, 5, 8]
    with h5py.File(out, "r") as f:
        assert [f[k].attrs["seed"] for k in ("traj_0", "traj_1", "traj_2")] == [5, 7, 8]
        assert np.array_equal(f["traj_1/obs/agent/qpos"][()], first) and f["traj_2/obs/agent/qpos"].shape == (6, 9)
    assert write_rendering(traj, out, "state", observe) == (3, 0)  # nothing new
    # Not reused: renderings of an older rendering version, or lacking what this version renders.
    with h5py.File(out, "a") as f:
        f["traj_0"].attrs["render_version"] = 0
    assert write_rendering(traj, out, "state", observe) == (3, 1) and calls[-1] == 5
    assert write_rendering(traj, out, "state", observe, needed=("tactile/left/depth",)) == (3, 3)


def test_a_rendering_killed_mid_task_keeps_its_finished_parts_and_resumes_to_the_same_file(tmp_path):
    from mani_skill_softvt.data.trajectory import rendering_parts_dir, write_rendering

    traj = tmp_path / "task0.h5"
    _stored_episodes(traj, [(5, 2), (6, 3), (7, 3), (8, 4), (9, 2)])
    calls, kill_at = [], [8]

    def observe(seed, states):
        calls.append(seed)
        if seed in kill_at:
            raise KeyboardInterrupt  # the session ends while the second part renders
        return [{"agent/qpos": row[:9] * 2} for row in states["actors/cube"]]

    out = tmp_path / "task0_state.h5"
    with pytest.raises(KeyboardInterrupt):
        write_rendering(traj, out, "state", observe, part_episodes=2)
    parts = rendering_parts_dir(out)
    assert not out.exists() and [p.name for p in parts.iterdir()] == ["part_0000.h5"]  # seeds 5 and 6
    (parts / "part_0003.h5").write_bytes(b"torn")  # an unreadable part is rendered again, not trusted
    kill_at.clear()
    assert write_rendering(traj, out, "state", observe, part_episodes=2) == (5, 3) and calls == [5, 6, 7, 8, 7, 8, 9]
    assert not parts.exists()
    whole = tmp_path / "whole_state.h5"
    assert write_rendering(traj, whole, "state", observe) == (5, 5)
    with h5py.File(out, "r") as a, h5py.File(whole, "r") as b:
        assert list(a.keys()) == list(b.keys()) == [f"traj_{i}" for i in range(5)]
        for k in a:
            assert dict(a[k].attrs) == dict(b[k].attrs)
            assert np.array_equal(a[k]["obs/agent/qpos"][()], b[k]["obs/agent/qpos"][()])
            assert np.array_equal(a[k]["actions"][()], b[k]["actions"][()])


def test_the_committed_samples_were_recorded_under_the_current_physics():
    from mani_skill_softvt.paths import REPO_DIR
    from mani_skill_softvt.physics.config import physics_signature

    for suite in ("object_soft", "object_rigid"):
        manifest = json.loads((REPO_DIR / "demo-data" / "sample" / suite / "manifest.json").read_text())
        assert manifest["physics"] == physics_signature(), suite


def test_two_runs_share_a_suites_tasks_through_its_task_locks(tmp_path):
    """A run waits for a task another run holds (the campaign's two lanes, one from the first task
    and one from the last) and goes on the moment it is free; other tasks are not held up."""
    import threading

    from mani_skill_softvt.data.demo_set import DemoSet

    demo_set = DemoSet(tmp_path, "object_soft")
    entered = {3: threading.Event(), 4: threading.Event()}

    def take(task):
        with demo_set.task_lock(task):
            entered[task].set()

    with demo_set.task_lock(3):
        waiting = [threading.Thread(target=take, args=(t,)) for t in (3, 4)]
        for t in waiting:
            t.start()
        assert entered[4].wait(5) and not entered[3].wait(0.3)
    assert entered[3].wait(5)
    for t in waiting:
        t.join(5)


def test_a_run_over_some_tasks_keeps_the_other_tasks_in_the_manifest_and_qc_report(dataset, tmp_path):
    """Two runs over one suite, each over its own tasks, leave one manifest and one QC report
    listing all of them, whichever wrote last; a run's returned report is its own tasks'."""
    import shutil

    from mani_skill_softvt.data.demo_set import DemoSet
    from mani_skill_softvt.data.seeds import train_seed
    from mani_skill_softvt.fileio import append_jsonl, atomic_write_json, read_json

    out, _ = dataset
    shutil.copytree(out / "object_soft", tmp_path / "object_soft")
    demo_set = DemoSet(tmp_path, "object_soft")
    other = {"task_id": 7, "generated": 5, "accepted": 5}  # as the other run reported task 7
    append_jsonl(demo_set.qc_log(7), {"seed": train_seed(7, 4), "accepted": True, "steps": 150, "r_max": 0.5})
    atomic_write_json(demo_set.qc_report, {"suite": "object_soft", "tasks": [other]})
    manifest = read_json(demo_set.manifest)
    manifest["train_seeds"]["7"] = [train_seed(7, 0), train_seed(7, 4)]
    atomic_write_json(demo_set.manifest, manifest)
    report = generate("object_soft", [3], 1, tmp_path)  # task 3 is complete: nothing recorded
    assert [r["task_id"] for r in report["tasks"]] == [3]
    assert [r["task_id"] for r in read_json(demo_set.qc_report)["tasks"]] == [3, 7]
    assert read_json(demo_set.qc_report)["tasks"][1] == other
    manifest = read_json(demo_set.manifest)
    assert manifest["train_seeds"]["7"] == [train_seed(7, 0), train_seed(7, 4)] and "3" in manifest["train_seeds"]
    assert manifest["id_eval_seeds"].keys() == manifest["train_seeds"].keys()


def test_a_task_another_run_rendered_meanwhile_is_not_rendered_again(tmp_path):
    """The render command picks its tasks before it takes their locks: a task the other lane
    rendered in between is found current under the lock and counted, not rendered (no env built)."""
    from mani_skill_softvt.data.demo_set import DemoSet
    from mani_skill_softvt.data.trajectory import RENDER_VERSION, episode_digest
    from mani_skill_softvt.demonstrations.render import _render_task

    demo_set = DemoSet(tmp_path, "object_soft")
    demo_set.dir.mkdir(parents=True)
    _stored_episodes(demo_set.trajectory(0), [(7, 3), (8, 4)])
    with h5py.File(demo_set.trajectory(0), "r") as a, h5py.File(demo_set.rendered(0, "state_dict"), "w") as b:
        for k in a:
            g = b.create_group(f"{k}/obs").parent
            g.attrs.update({"states_sha256": episode_digest(a[k]), "render_version": RENDER_VERSION})
    progress = []

    class Queue:
        put = progress.append

    assert _render_task("object_soft", 0, str(tmp_path), "state_dict", None, Queue) == (0, 2, 0)
    assert progress == [1, 1]
