"""Episode videos: the frame layout as a pure function, and a short re-run written to mp4 and read back."""

import warnings

import numpy as np
import pytest

from mani_skill_softvt.evaluation.videos import (WARN, compare_records, compose_frame, gauge_box, rt_strip,
                                                 video_name)

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

INSTRUCTION = "Pick up the soft cream-colored cube and place it in the basket."


def _images():
    """Flat-coloured camera (batched, as in obs) and tactile images, so each panel is recognisable."""
    base = np.full((1, 224, 224, 3), (200, 0, 0), np.uint8)
    hand = np.full((224, 224, 3), (0, 200, 0), np.uint8)
    left = np.full((240, 320, 3), (0, 0, 200), np.uint8)
    right = np.full((240, 320, 3), (200, 200, 0), np.uint8)
    return base, hand, left, right


def _warn_pixels(image):
    return int(np.all(image == np.array(WARN, np.uint8), axis=-1).sum())


def test_frame_layout_panels_and_sizes():
    base, hand, left, right = _images()
    frame = compose_frame(base, hand, left, right, [0.0, 0.2, 0.4], instruction=INSTRUCTION, max_steps=300)
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape[0] % 16 == 0 and frame.shape[1] % 16 == 0  # H.264-friendly, no rescale by imageio
    tactile_w = round(320 * 224 / 240)
    assert frame.shape[1] >= 2 * 224 + 2 * tactile_w and frame.shape[0] > 224
    # Panel centres (below the captions) carry each source's colour: base | wrist | left | right.
    xs = [112, 224 + 112, 448 + tactile_w // 2, 448 + tactile_w + tactile_w // 2]
    for x, src in zip(xs, (base[0], hand, left, right)):
        assert (frame[150, x] == src[0, 0]).all(), x
    # The strip under the panels is not image content.
    assert not (frame[224:] == base[0, 0, 0]).all(axis=-1).any()


def test_a_small_policy_camera_is_shown_enlarged_pixel_for_pixel():
    rng = np.random.default_rng(0)
    base, hand = (rng.integers(0, 256, (84, 84, 3), dtype=np.uint8) for _ in range(2))
    _, _, left, right = _images()
    frame = compose_frame(base, hand, left, right, [0.0], max_steps=300)
    panel = frame[40:224, :224]  # below the caption
    colours = {tuple(c) for c in base.reshape(-1, 3)}
    assert frame.shape[0] > 224 and all(tuple(c) in colours for c in panel.reshape(-1, 3))  # no blended pixels


def test_gauge_and_trace_turn_warning_colour_beyond_tolerance():
    width = 1048
    calm = rt_strip([0.0, 0.5, 0.8], width, 300, INSTRUCTION, success=True, dsr_success=True)
    over = rt_strip([0.0, 0.5, 1.4], width, 300, INSTRUCTION, success=True, dsr_success=False)
    assert _warn_pixels(calm) == 0
    x0, y0, x1, y1 = gauge_box(width)
    gauge = over[y0 + 2:y1 - 1, x0 + 2:x1]
    assert _warn_pixels(gauge) > 0.5 * (1.4 / 2.0) * gauge.shape[0] * gauge.shape[1]
    # The gauge fills in proportion to R_t: 0.8 reaches further than 0.5.
    half = rt_strip([0.5], width, 300, "", False, False)
    row = (y0 + y1) // 2
    filled = [int((s[row, x0 + 1:x1 - 1] != s[row, x1 - 3]).any(axis=-1).sum()) for s in (half, calm)]
    assert filled[0] < filled[1]


def test_bad_inputs_are_named():
    base, hand, left, right = _images()
    with pytest.raises(ValueError, match="batch of 2"):
        compose_frame(np.concatenate([base, base]), hand, left, right, [0.0])
    with pytest.raises(ValueError, match="uint8"):
        compose_frame(base.astype(np.float32), hand, left, right, [0.0])
    with pytest.raises(ValueError, match="r_trace is empty"):
        compose_frame(base, hand, left, right, [])
    with pytest.raises(ValueError, match="NaN"):
        compose_frame(base, hand, left, right, [0.0, float("nan")])


def test_names_and_record_comparison():
    ep = {"suite": "object_soft", "task_id": 3, "condition": "mass_high", "seed": 50003000}
    # One file per episode: any change of task, condition or seed gives another name.
    names = {video_name("run", {**ep, **change}) for change in
             ({}, {"task_id": 4}, {"condition": "id"}, {"seed": 50003001})}
    assert len(names) == 4 and all(n.endswith(".mp4") for n in names)
    stored = {"deformation_trace": [0.0, 1e-4, 2e-4], "success": False, "dsr_success": False, "r_max": 0.02}
    same = {**stored, "tau_o": 0.01}
    assert compare_records(stored, same, capped=False) == []
    assert compare_records(stored, {**same, "deformation_trace": [0.0, 1e-4]}, capped=True) == []
    diffs = compare_records(stored, {**same, "deformation_trace": [0.0, 3e-4, 2e-4], "r_max": 0.03}, capped=False)
    assert any("trace" in d for d in diffs) and any("r_max" in d for d in diffs)


@pytest.mark.slow  # a rendered episode and its mp4; the frame layout is checked by default
def test_short_episode_video_is_the_stored_episode(tmp_path):
    """A capped `hold` episode, evaluated in state_dict mode, re-run into an mp4: same trace, right frames."""
    import gymnasium as gym
    import imageio

    import mani_skill_softvt  # noqa: F401
    from mani_skill_softvt.evaluation.policies import load_policy
    from mani_skill_softvt.evaluation.run import RunConfig
    from mani_skill_softvt.evaluation.runner import run_episode
    from mani_skill_softvt.evaluation.videos import record_episode_video
    from mani_skill_softvt.evaluation.wrapper import DSRWrapper

    steps = 6
    ep = {"suite": "object_soft", "task_id": 3, "condition": "id", "seed": 50003000}
    env = DSRWrapper(gym.make("SoftVTObjectSoft-v1", task_id=3, obs_mode="state_dict", control_mode="pd_ee_pose",
                              max_episode_steps=steps))
    try:
        stored = run_episode(env, load_policy("hold"), ep)
    finally:
        env.close()
    path = tmp_path / "videos" / video_name("t", ep)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # a re-run that differs from the record fails here
        rerun = record_episode_video(stored, RunConfig.resolve("hold"), path, max_steps=steps)
    assert rerun["steps"] == steps and rerun["deformation_trace"] == stored["deformation_trace"]
    frames = imageio.mimread(path, memtest=False)
    assert len(frames) == steps + 1  # the reset and every step
    assert frames[0].shape == compose_frame(*_images(), [0.0]).shape
    assert not list(tmp_path.glob("videos/.*"))  # the atomic write left no temporary file
    with pytest.raises(ValueError, match="rgb\\+tactile"):
        record_episode_video(stored, RunConfig.resolve("hold"), tmp_path / "x.mp4", obs_mode="rgb")
