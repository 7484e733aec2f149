"""Episode videos: both cameras and both tactile images side by side, the R_t trace below.

A frame is ``base camera | wrist camera | left tactile | right tactile`` (tactile images, markers
already drawn by the sensor, scaled to the camera height) over a strip with the instruction, the
step, R_t, R_max, success so far and the R_t trace against the tolerance line R_t = 1.

``record_episode_video`` re-runs a stored episode (same suite, task, condition and seed: the
physics is deterministic, so it is the same episode) through the runner's own episode loop in
``rgb+tactile`` mode and streams the frames to an mp4.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import cv2
import imageio
import numpy as np

from ..fileio import atomic_write
from ..contracts.observations import CAMERAS, SIDES, camera_key, lookup, tactile_key
from ..tasks import constants as C
from ..tasks.suites import get_suite
from .runner import run_episode
from .wrapper import make_env

FPS = 20  # the control rate: one frame per env step plays in real time
STRIP_HEIGHT = 112
MACRO_BLOCK = 16  # H.264 wants sizes divisible by 16; padding avoids imageio's silent rescale
PANEL_HEIGHT = 224  # panels are at least this tall: an 84-px policy's cameras are shown enlarged, pixels kept
BACKGROUND = (28, 28, 28)
TEXT = (235, 235, 235)
MUTED = (150, 150, 150)
OK = (60, 180, 75)  # colours are RGB: cv2 draws channel values and does not care about order
WARN = (230, 50, 40)
GAUGE_MAX = 2.0  # the R_t gauge spans [0, 2]: the tolerance sits in its middle
FONT = cv2.FONT_HERSHEY_SIMPLEX


def as_image(x) -> np.ndarray:
    """An (H, W, 3) uint8 array from an observation image: numpy or torch, batched (1, H, W, 3) or not."""
    if hasattr(x, "detach"):  # torch tensor, possibly on a GPU
        x = x.detach().cpu().numpy()
    x = np.asarray(x)
    if x.ndim == 4:
        if x.shape[0] != 1:
            raise ValueError(f"expected one env's image, got a batch of {x.shape[0]} (videos need num_envs=1)")
        x = x[0]
    if x.ndim != 3 or x.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) RGB image, got shape {x.shape}")
    if x.dtype != np.uint8:
        raise ValueError(f"expected a uint8 image, got {x.dtype}")
    return x


def resize_to_height(image: np.ndarray, height: int) -> np.ndarray:
    """``image`` scaled to ``height`` rows, aspect ratio kept."""
    h, w = image.shape[:2]
    if h == height:
        return image
    width = max(1, round(w * height / h))
    # AREA keeps the marker dots when shrinking; NEAREST shows a small camera's pixels as they are.
    interp = cv2.INTER_AREA if height < h else cv2.INTER_NEAREST if h < PANEL_HEIGHT else cv2.INTER_LINEAR
    return cv2.resize(image, (width, height), interpolation=interp)


def _label(image: np.ndarray, text: str) -> np.ndarray:
    """A copy of ``image`` with a small caption in its top-left corner (dark outline: readable on any scene)."""
    out = np.ascontiguousarray(image).copy()
    cv2.putText(out, text, (5, 15), FONT, 0.42, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(out, text, (5, 15), FONT, 0.42, TEXT, 1, cv2.LINE_AA)
    return out


def _fit_text(text: str, width: int, scale: float) -> str:
    """``text`` cut (with '...') to fit ``width`` pixels."""
    if cv2.getTextSize(text, FONT, scale, 1)[0][0] <= width:
        return text
    while text and cv2.getTextSize(text + "...", FONT, scale, 1)[0][0] > width:
        text = text[:-1]
    return text + "..."


def gauge_box(width: int) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of the R_t gauge inside a strip of ``width`` pixels (bottom right)."""
    return width - 236, STRIP_HEIGHT - 26, width - 12, STRIP_HEIGHT - 10


def rt_strip(r_trace, width: int, max_steps: int, instruction: str, success: bool, dsr_success: bool,
             collapsed: bool = False) -> np.ndarray:
    """The strip under the panels: text, the R_t trace so far against the tolerance, and a gauge of the last R_t.

    ``r_trace`` holds R_t from the reset on (step 0), so its last value is the current step's.
    The trace and the gauge turn ``WARN`` where R_t > 1 (beyond the tolerance).
    """
    r = np.asarray(r_trace, dtype=np.float64).reshape(-1)
    if r.size == 0:
        raise ValueError("r_trace is empty: it needs at least the reset's R_t")
    if not np.all(np.isfinite(r)):
        raise ValueError("r_trace has NaN or infinite values")
    if max_steps < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    if width < 480:
        raise ValueError(f"strip width must be >= 480 px, got {width}")
    strip = np.full((STRIP_HEIGHT, width, 3), BACKGROUND, np.uint8)
    step, rt = r.size - 1, float(r[-1])
    cv2.putText(strip, _fit_text(instruction, width - 16, 0.5), (8, 18), FONT, 0.5, TEXT, 1, cv2.LINE_AA)

    # Plot: x = step over the whole episode length (the curve grows left to right), y up to 1.5 at least.
    px0, py0, px1, py1 = 8, 28, width - 250, STRIP_HEIGHT - 8
    ymax = max(1.5, 1.1 * float(r.max()))
    cv2.rectangle(strip, (px0, py0), (px1, py1), MUTED, 1)

    def to_px(i, v):
        return (int(round(px0 + (px1 - px0) * i / max(max_steps, step))),
                int(round(py1 - (py1 - py0) * min(v, ymax) / ymax)))

    ytol = to_px(0, 1.0)[1]
    for x in range(px0, px1, 8):  # dashed tolerance line
        cv2.line(strip, (x, ytol), (min(x + 4, px1), ytol), MUTED, 1)
    cv2.putText(strip, "tol", (px1 - 24, ytol - 3), FONT, 0.35, MUTED, 1, cv2.LINE_AA)
    pts = [to_px(i, v) for i, v in enumerate(r)]
    for i in range(1, len(pts)):
        cv2.line(strip, pts[i - 1], pts[i], WARN if r[i] > 1.0 else OK, 1, cv2.LINE_AA)

    # Text block and gauge, right of the plot.
    tx = width - 236
    why = " (collapse)" if collapsed and not dsr_success else ""  # DSR lost with R_t under the line
    state = f"success {'yes' if success else 'no'}   DSR {'yes' if dsr_success else 'no'}{why}"
    cv2.putText(strip, f"step {step}/{max_steps}   R_max {float(r.max()):.2f}", (tx, 44), FONT, 0.45, TEXT, 1,
                cv2.LINE_AA)
    cv2.putText(strip, state, (tx, 64), FONT, 0.45, TEXT, 1, cv2.LINE_AA)
    cv2.putText(strip, f"R_t {rt:.2f}", (tx, STRIP_HEIGHT - 30), FONT, 0.45, TEXT, 1, cv2.LINE_AA)
    gx0, gy0, gx1, gy1 = gauge_box(width)
    fill = gx0 + int(round((gx1 - gx0) * min(max(rt, 0.0), GAUGE_MAX) / GAUGE_MAX))
    if fill > gx0:
        cv2.rectangle(strip, (gx0, gy0), (fill, gy1), WARN if rt > 1.0 else OK, -1)
    cv2.rectangle(strip, (gx0, gy0), (gx1, gy1), MUTED, 1)
    xt = (gx0 + gx1) // 2  # R_t = 1 tick
    cv2.line(strip, (xt, gy0 - 3), (xt, gy1 + 3), TEXT, 1)
    return strip


def _pad_to(image: np.ndarray, multiple: int) -> np.ndarray:
    h, w = image.shape[:2]
    ph, pw = -h % multiple, -w % multiple
    if not (ph or pw):
        return image
    return cv2.copyMakeBorder(image, 0, ph, 0, pw, cv2.BORDER_CONSTANT, value=BACKGROUND)


def compose_frame(base_rgb, hand_rgb, tactile_left, tactile_right, r_trace, *, instruction: str = "",
                  max_steps: int = 300, success: bool = False, dsr_success: bool = False,
                  collapsed: bool = False) -> np.ndarray:
    """One video frame (H, W, 3) uint8, H and W multiples of 16 (pure: no env, no I/O).

    Panels left to right: base camera, wrist camera, left and right tactile images (scaled to the
    base camera's height, at least :data:`PANEL_HEIGHT`; the sensor has drawn the markers already).
    Below them the strip of ``rt_strip``: ``r_trace`` is R_t from the reset to the current step;
    ``collapsed``: a tet has collapsed so far (DSR is lost whatever R_t shows).
    """
    base = as_image(base_rgb)
    height = max(base.shape[0], PANEL_HEIGHT)
    if base.shape[0] < height:  # a small camera (a policy's 84 px) enlarged pixel for pixel: what the policy saw
        base = cv2.resize(base, (round(base.shape[1] * height / base.shape[0]), height), interpolation=cv2.INTER_NEAREST)
    panels = [_label(base, "base camera"), _label(resize_to_height(as_image(hand_rgb), height), "wrist camera"),
              _label(resize_to_height(as_image(tactile_left), height), "tactile left"),
              _label(resize_to_height(as_image(tactile_right), height), "tactile right")]
    top = np.concatenate(panels, axis=1)
    strip = rt_strip(r_trace, top.shape[1], max_steps, instruction, success, dsr_success, collapsed)
    return _pad_to(np.concatenate([top, strip], axis=0), MACRO_BLOCK)


def frame_from_obs(obs: dict, r_trace, info: dict, instruction: str, max_steps: int) -> np.ndarray:
    """``compose_frame`` fed from an rgb+tactile observation and a DSRWrapper ``info``."""
    try:
        images = [lookup(obs, camera_key(c)) for c in CAMERAS] + [lookup(obs, tactile_key(s, "rgb")) for s in SIDES]
    except (KeyError, TypeError) as e:
        raise ValueError(f"observation lacks {e}: videos need obs_mode 'rgb+tactile' (cameras and tactile images)") \
            from e
    return compose_frame(*images, r_trace, instruction=instruction, max_steps=max_steps,
                         success=bool(info["task_success"]), dsr_success=bool(info["dsr_success"]),
                         collapsed=bool(info.get("collapsed_steps")))


def video_name(stem: str, episode: dict) -> str:
    """File name of an episode's video: ``<stem>_task<k>_<condition>_<seed>.mp4``."""
    return f"{stem}_task{int(episode['task_id'])}_{episode['condition']}_{int(episode['seed'])}.mp4"


def compare_records(stored: dict, rerun: dict, capped: bool) -> list[str]:
    """Differences between a stored record and its re-run (empty when they agree).

    A capped re-run (fewer steps) is compared on its trace prefix only.
    """
    out = []
    a = np.asarray(stored.get("deformation_trace", []), np.float64)
    b = np.asarray(rerun["deformation_trace"], np.float64)
    if a.size:
        n = min(a.size, b.size)
        if (not capped and a.size != b.size) or not np.allclose(a[:n], b[:n], rtol=1e-5, atol=1e-6 * rerun["tau_o"]):
            out.append(f"deformation trace differs (stored {a.size} values, re-run {b.size})")
    if not capped:
        for key in ("success", "dsr_success", "r_max"):
            if key in stored and not np.isclose(float(stored[key]), float(rerun[key]), rtol=1e-5, atol=1e-9):
                out.append(f"{key}: stored {stored[key]}, re-run {rerun[key]}")
    return out


def record_episode_video(episode: dict, run, path, obs_mode: str = "rgb+tactile", max_steps: int | None = None,
                         fps: int = FPS) -> dict:
    """Re-run ``episode`` with the policy of ``run`` (a :class:`~mani_skill_softvt.evaluation.run.RunConfig`:
    its control mode and camera size) and write its video to ``path`` (mp4, atomically); the
    re-run record.

    ``episode`` is an evaluation record or just its (suite, task_id, condition, seed). Where it is
    a record (it has a ``deformation_trace``), the re-run is checked against it and a
    ``RuntimeWarning`` says where they differ (a non-deterministic policy, another package
    version). ``max_steps`` truncates the episode (short previews, tests). The cameras render at the
    run's camera size, as in its evaluation.
    """
    missing = [k for k in ("suite", "task_id", "condition", "seed") if k not in episode]
    if missing:
        raise ValueError(f"episode lacks {missing}: pass an evaluation record or a protocols.episodes() entry")
    get_suite(episode["suite"])  # a clear error for an unknown suite before any work
    if not obs_mode.endswith("+tactile") or not obs_mode.startswith("rgb"):
        raise ValueError(f"videos need camera and tactile images: obs_mode 'rgb+tactile', got '{obs_mode}'")
    if max_steps is not None and max_steps < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    _require_ffmpeg()

    horizon = max_steps or C.MAX_EPISODE_STEPS
    limit = {"max_episode_steps": max_steps} if max_steps else {}
    policy = run.policy.load()
    env = make_env(episode["suite"], int(episode["task_id"]), obs_mode=obs_mode, control_mode=run.control_mode,
                   camera_size=run.camera_size, **limit)
    result = {}

    def write(tmp: Path) -> None:
        r_trace = []
        # macro_block_size=1: compose_frame already pads to 16, so imageio must not rescale.
        with imageio.get_writer(tmp, format="FFMPEG", fps=fps, codec="libx264", quality=7,
                                macro_block_size=1, pixelformat="yuv420p") as writer:
            def on_step(obs, info):
                r_trace.append(float(info["deformation_ratio"]))
                writer.append_data(frame_from_obs(obs, r_trace, info, env.unwrapped.instruction, horizon))

            result["record"] = run_episode(env, policy, episode, on_step=on_step)

    try:
        atomic_write(Path(path), write)
    finally:
        env.close()
    rec = result["record"]
    diffs = compare_records(episode, rec, capped=max_steps is not None)
    if diffs:
        warnings.warn(f"video of {video_name('episode', episode)} is not the stored episode: " + "; ".join(diffs),
                      RuntimeWarning, stacklevel=2)
    return rec


def _require_ffmpeg() -> None:
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError as e:
        raise RuntimeError("episode videos need imageio-ffmpeg: pip install imageio-ffmpeg") from e
