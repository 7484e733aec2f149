"""How a rigid twin sits in the scripted pinch, and what the tactile model shows of it.

    python -m softvt_campaign.studies.twin_pinch            # the cube twin: 4 closures x 4 seeds x 2 yaws
    python -m softvt_campaign.studies.twin_pinch --pivot    # pastry003's and pastry005's twins, lightest closures

Each grasp is the calibration's grasp, lift and hold (``calibration.protocol.STEPS``) on
``SoftGraspLift-v1`` with the hand at its default heading (yaw ``0``) or turned to the object's
settled yaw (``align``, as calibration does, without its jitter). At hold step 10 (counting from 0:
0.55 s into the 2 s hold), per pad:

- the tilt of the object's face nearest the pad against the pad plane (the faces are those of the
  modelled shape's box in its rest frame: the cube's own faces, the box a pastry is modelled in);
- the pad's normal force (the env's ``pad_normal_force``) and the patch the sensor reports (area
  in view, peak indentation);
- the gel model's patch for a flat face at that tilt and force (:func:`flat_face_patch`; it takes
  the hinge along the pad's length, as the yawed grasps tilt it: a tilt about pad x is an estimate);
- the same gel balance on the twin's hull as PhysX holds it (:func:`hull_patch`), solved apart
  from the sensor on a finer grid: what the sensor's patch should be;

and per grasp the object's turn and slip relative to the hand from the end of the close to the end
of the hold. Writes ``<out>/twin_pinch.json`` (every grasp; a re-run skips those already there)
and ``twin_pinch.md`` (one table per asset, one row per grasp).

Since tactile model 3 the sensor touches a twin on the hull PhysX collides (its cooked convex
shapes); model 2 rendered the twin's tet boundary, which sits some 0.35 mm outside that hull, so
the whole pad in view read as pressed at any force (``twin_pinch_tactile_model2.md`` keeps those
grasps). A result file of another tactile model is refused.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from mani_skill_softvt import tasks  # noqa: F401  (registers SoftGraspLift-v1)
from mani_skill_softvt.calibration import protocol as P
from mani_skill_softvt.calibration.stats import slip_distance
from mani_skill_softvt.expert.grasp_script import GraspPlan, run_grasp_script
from mani_skill_softvt.fileio import atomic_write, atomic_write_json, read_json
from mani_skill_softvt.contracts.observations import SIDES
from mani_skill_softvt.paths import REPO_DIR
from mani_skill_softvt.physics.config import physics_signature, signature_mismatch
from mani_skill_softvt.physics.rigid import rigid_nodes
from mani_skill_softvt.physics.transforms import pose_wxyz_to_matrix, quat_wxyz_to_matrix, yaw_between
from mani_skill_softvt.tactile import constants as TC
from mani_skill_softvt.tactile.gel import foundation_stiffness
from mani_skill_softvt.tactile.sensor import world_to_pad
from mani_skill_softvt.tasks.constants import GEL_PAD_HALF_EXTENTS
from mani_skill_softvt.tasks.suites import SUITES

TACTILE_MODEL = SUITES["object_rigid"].tactile_model  # the version of the twins' frames
HOLD_STEP = 10  # index in the hold (from 0): lifted and at rest in the grasp
CUBE = {"rigid_stw_cube_hq": (0.4, 0.5, 0.7, 0.9)}
# The light end of the soft cards' envelopes, where these twins pivot or slip (docs/limitations.md):
# pastry003's g_min and a step above, pastry005's g_min and a step above.
PIVOT = {"rigid_pastry003": (0.5, 0.633), "rigid_pastry005": (0.35, 0.4)}
YAW_MODES = ("0", "align")
PAD_WIDTH, PAD_LENGTH = 2 * GEL_PAD_HALF_EXTENTS[0], 2 * GEL_PAD_HALF_EXTENTS[1]  # m: across / along the finger
VIEW_HEIGHT = min(PAD_LENGTH, TC.FOV_HEIGHT)  # m of the pad's length in view
FACES = ("+x", "+y", "+z", "-x", "-y", "-z")
HULL_GRID = 0.05e-3  # m: the pad sampled for the hull's own patch, finer than the sensor's 0.118 mm grid


# ------------------------------------------------------------------------------ pure functions

def flat_face_patch(force: float, tilt: float, stiffness: float = foundation_stiffness(), length: float = PAD_LENGTH,
                    width: float = PAD_WIDTH, view_height: float = VIEW_HEIGHT) -> tuple[float, float]:
    """(area in view m^2, peak indentation m) of a rigid flat face tilted by ``tilt`` (rad) about
    the pad's length, pressed with ``force`` (N) into a Winkler gel of ``stiffness`` (Pa/m).

    The face is hinged on a pad edge: the gel sinks d at the edge and d - x tan(tilt) at x, so a
    strip w = d / tan(tilt) carries F = K L d^2 / (2 tan(tilt)). Once w would exceed the pad's width
    the face presses all of it: F = K L W (d - tan(tilt) W / 2). Both give d = W tan(tilt) at the
    switch; at tilt 0 the second is the uniform F / (K L W)."""
    if force <= 0.0:
        return 0.0, 0.0
    t = np.tan(tilt)
    if force <= stiffness * length * width ** 2 * t / 2:  # the strip is narrower than the pad
        d = np.sqrt(2 * force * t / (stiffness * length))
        return float(d / t * view_height), float(d)
    return float(width * view_height), float(force / (stiffness * length * width) + t * width / 2)


def convex_gap(points_xy: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Height (m) above the pad plane of the convex hull of ``vertices`` (pad frame, +z towards
    the object) over each pad point ``points_xy`` (P, 2): the hull's lowest z on the vertical line
    there, +inf where the line misses it. Exact for a convex body: on the line (x, y, z) the hull
    is the z range every facet plane n.x + c <= 0 allows."""
    eq = ConvexHull(vertices).equations  # (F, 4): outward n, offset c
    n, c = eq[:, :3], eq[:, 3]
    out = np.empty(len(points_xy))
    for k in range(0, len(points_xy), 8192):  # chunks: points x facets stays small
        rhs = -(c[None, :] + points_xy[k:k + 8192] @ n[:, :2].T)  # n_z z <= rhs for each facet
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = rhs / n[None, :, 2]
        lo = np.max(np.where(n[None, :, 2] < 0, bound, -np.inf), axis=1)  # facets facing the pad: from below
        hi = np.min(np.where(n[None, :, 2] > 0, bound, np.inf), axis=1)
        side = np.all(np.where(n[None, :, 2] == 0, rhs >= 0, True), axis=1)  # walls parallel to the line
        out[k:k + 8192] = np.where((lo <= hi) & side, lo, np.inf)
    return out


def winkler_patch(gap: np.ndarray, in_view: np.ndarray, force: float, pixel_area: float,
                  stiffness: float = foundation_stiffness()) -> tuple[float, float]:
    """(area m^2, peak indentation m) in view (``in_view`` mask) of a rigid surface of ``gap`` map
    (m, +inf: none) pressed with ``force`` (N) into a Winkler gel: the sink d with K a sum(max(0, d - gap)) = F,
    by bisection (the sensor solves the same balance in closed form on its own grid)."""
    finite = gap[np.isfinite(gap)]
    if force <= 0.0 or finite.size == 0:
        return 0.0, 0.0
    lo, hi = finite.min(), finite.min() + force / (stiffness * pixel_area)  # hi: one pixel carries it all
    for _ in range(200):
        d = 0.5 * (lo + hi)
        lo, hi = (d, hi) if stiffness * pixel_area * np.maximum(d - finite, 0.0).sum() < force else (lo, d)
    d = 0.5 * (lo + hi)
    pressed = (d - gap > 0) & in_view
    return float(pressed.sum() * pixel_area), float((d - gap[pressed]).max()) if pressed.any() else 0.0


def nearest_face_tilt(shape_rotation: np.ndarray, pad_rotation: np.ndarray) -> dict:
    """The modelled box's face whose outward normal points most nearly into the pad (against the
    pad's +z), its tilt (deg) against the pad plane and the tilt's parts about pad x and pad y."""
    normals = np.concatenate([shape_rotation.T, -shape_rotation.T]) @ pad_rotation  # faces' normals, pad frame
    k = int(np.argmax(-normals[:, 2]))
    n = normals[k]
    return {"face": FACES[k], "tilt_deg": float(np.degrees(np.arccos(np.clip(-n[2], -1.0, 1.0)))),
            "tilt_about_pad_x_deg": float(np.degrees(np.arctan2(n[1], -n[2]))),
            "tilt_about_pad_y_deg": float(np.degrees(np.arctan2(n[0], -n[2])))}


def turn_in_hand_deg(hand_quats, object_quats) -> float:
    """Angle (deg) the object turned relative to the hand between two samples (wxyz quaternions)."""
    rel = [quat_wxyz_to_matrix(h).T @ quat_wxyz_to_matrix(o) for h, o in zip(hand_quats, object_quats)]
    return float(np.degrees(Rotation.from_matrix(rel[1] @ rel[0].T).magnitude()))


def grasp_key(r: dict) -> tuple:
    return r["asset"], round(r["closure"], 6), r["seed"], r["yaw_mode"]


# ------------------------------------------------------------------------ the simulator's side

def pad_snapshot(u, body, side: str, frame) -> dict:
    """One pad now: the face's tilt, the force, the sensor's patch (``frame``) and the flat-face prediction."""
    pose = u.pad_pose(side)
    force = u.pad_normal_force(side, pose)
    body_pose = pose_wxyz_to_matrix(body.pose7())
    shape_rotation = body_pose[:3, :3] @ quat_wxyz_to_matrix(np.asarray(u.objects.specs["object"].rest_pose)[3:])
    tilt = nearest_face_tilt(shape_rotation, pose[:3, :3])
    area, peak = flat_face_patch(force, np.radians(tilt["tilt_deg"]))
    hull_area, hull_peak = hull_patch([world_to_pad(rigid_nodes(v, body.pose7()), pose) for v, _ in body.surface_parts],
                                      force)
    return {**tilt, "force_n": force, "sensor_area_mm2": 1e6 * float(frame.contact.sum()) * TC.PIXEL_SIZE ** 2,
            "sensor_peak_um": 1e6 * float(frame.depth.max()), "flat_face_area_mm2": 1e6 * area,
            "flat_face_peak_um": 1e6 * peak, "hull_area_mm2": 1e6 * hull_area, "hull_peak_um": 1e6 * hull_peak}


def hull_patch(parts_pad: list[np.ndarray], force: float) -> tuple[float, float]:
    """:func:`winkler_patch` over the whole pad of the union of convex parts (each part's
    vertices in the pad frame): the lowest of the parts' :func:`convex_gap` at each point."""
    xs = np.arange(-PAD_WIDTH / 2 + HULL_GRID / 2, PAD_WIDTH / 2, HULL_GRID)
    ys = np.arange(-PAD_LENGTH / 2 + HULL_GRID / 2, PAD_LENGTH / 2, HULL_GRID)
    gx, gy = np.meshgrid(xs, ys)
    points = np.stack([gx.ravel(), gy.ravel()], 1)
    gap = np.min([convex_gap(points, vertices) for vertices in parts_pad], axis=0)
    return winkler_patch(gap, np.abs(gy.ravel()) <= VIEW_HEIGHT / 2, force, HULL_GRID ** 2)


def run_grasp(env, asset: str, closure: float, seed: int, yaw_mode: str) -> dict:
    """Reset ``env`` (a twin's) to ``seed``, grasp, lift and hold; the grasp's record."""
    env.reset(seed=seed)
    u = env.unwrapped
    body = u.objects.bodies["object"]
    object_yaw = yaw_between(u.rest_vertices("object"), u.settled_nodes("object"))
    yaw = object_yaw if yaw_mode == "align" else float(yaw_mode)
    pads, object_quat = {}, {}

    def on_step(phase, i, n):
        if phase == "hold" and i == HOLD_STEP:
            frames = u.tactile_frames()
            pads.update({side: pad_snapshot(u, body, side, frames[side]) for side in SIDES})
        if i == n - 1:
            object_quat[phase] = body.pose7()[3:]

    rec = run_grasp_script(env, GraspPlan(closure=closure, yaw=float(yaw), steps=dict(P.STEPS)), on_step=on_step)
    ends = [int(np.flatnonzero(rec["phase"] == phase)[-1]) for phase in ("close", "hold")]
    return {"asset": asset, "closure": closure, "seed": seed, "yaw_mode": yaw_mode,
            "object_yaw_deg": float(np.degrees(object_yaw)), "grasp_yaw_deg": float(np.degrees(yaw)),
            "turn_deg": turn_in_hand_deg(rec["tcp_quat"][ends], [object_quat["close"], object_quat["hold"]]),
            "slip_mm": 1e3 * slip_distance(rec["object_centroid"][ends], rec["tcp"][ends], rec["tcp_quat"][ends]),
            "lifted": bool(rec["object_min_z"][ends[1]] >= P.LIFT_THRESHOLD), "pads": pads}


def run(plan: dict, seeds, yaw_modes, path: Path) -> list[dict]:
    """Every (asset, closure, seed, yaw mode) of ``plan`` not yet in ``path``; all grasps there."""
    done = (read_json(path) if path.exists() else
            {"physics": physics_signature(), "tactile_model": TACTILE_MODEL, "grasps": []})
    stale = signature_mismatch(done.get("physics"))
    if done.get("tactile_model", 2) != TACTILE_MODEL:  # files from before the key was kept are model 2's
        stale.append(f"tactile model {done.get('tactile_model', 2)}, this package renders twins in {TACTILE_MODEL}")
    if stale:
        raise ValueError(f"{path} holds grasps run under other physics or touch ({'; '.join(stale)}); "
                         "move it away to re-run")
    have = {grasp_key(r) for r in done["grasps"]}
    todo = [(a, g, s, y) for a, closures in plan.items() for g in closures for s in seeds for y in yaw_modes
            if (a, round(g, 6), s, y) not in have]
    env, env_asset = None, None
    try:
        for a, g, s, y in tqdm(todo, desc="twin pinch", unit="grasp"):
            if a != env_asset:  # one env per asset: a reset re-places the same twin
                if env is not None:
                    env.close()
                env = gym.make("SoftGraspLift-v1", obs_mode="state", control_mode="pd_ee_pose", asset_id=a)
                env_asset = a
            done["grasps"].append(run_grasp(env, a, g, s, y))
            done["grasps"].sort(key=grasp_key)
            write(done, path)
    finally:
        if env is not None:
            env.close()
    return done["grasps"]


# ------------------------------------------------------------------------------------ reporting

def pair(r: dict, key: str, fmt: str) -> str:
    return " / ".join(format(r["pads"][side][key], fmt) for side in SIDES) if r["pads"] else "-"


def format_tables(grasps: list[dict]) -> str:
    lines = [f"Rigid twins in the scripted pinch at hold step {HOLD_STEP}; per pad left / right. "
             "Tilt: the face nearest the pad against the pad plane. Flat face: the gel model for a flat face at that "
             f"tilt and force. Hull: the same gel balance on the twin's PhysX hull, computed apart from the sensor "
             f"(convex_gap, winkler_patch). Sensor: tactile model {TACTILE_MODEL}. Turn, slip: the object relative to the hand, end of close to end of hold."]
    for asset in sorted({r["asset"] for r in grasps}):
        lines += ["", f"### {asset}", "",
                  "| closure | grasp yaw | seed | object yaw deg | tilt deg | F N | sensor mm^2 | sensor peak um "
                  "| flat face mm^2 | flat face peak um | hull mm^2 | hull peak um | turn deg | slip mm | lifted |",
                  "|" + "---|" * 15]
        for r in (r for r in grasps if r["asset"] == asset):
            lines.append(f"| {r['closure']} | {r['yaw_mode']} | {r['seed']} | {r['object_yaw_deg']:.2f} | "
                         f"{pair(r, 'tilt_deg', '.2f')} | {pair(r, 'force_n', '.2f')} | {pair(r, 'sensor_area_mm2', '.0f')} | "
                         f"{pair(r, 'sensor_peak_um', '.0f')} | {pair(r, 'flat_face_area_mm2', '.0f')} | "
                         f"{pair(r, 'flat_face_peak_um', '.0f')} | {pair(r, 'hull_area_mm2', '.0f')} | "
                         f"{pair(r, 'hull_peak_um', '.0f')} | {r['turn_deg']:.2f} | {r['slip_mm']:.2f} | "
                         f"{r['lifted']} |")
    return "\n".join(lines) + "\n"


def write(result: dict, path: Path) -> None:
    atomic_write_json(path, result)
    atomic_write(path.with_suffix(".md"), lambda tmp: tmp.write_text(format_tables(result["grasps"])))


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(prog="python -m softvt_campaign.studies.twin_pinch", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--assets", nargs="+", default=None, help=f"twin asset ids (default {list(CUBE)})")
    ap.add_argument("--closures", nargs="+", type=float, default=None, help=f"default {CUBE['rigid_stw_cube_hq']}")
    ap.add_argument("--pivot", action="store_true", help=f"the pivoting twins at their light closures: {PIVOT}")
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3])
    ap.add_argument("--yaw", nargs="+", default=list(YAW_MODES), help="'align' or a hand yaw in rad ('0': default heading)")
    ap.add_argument("--out", type=Path, default=REPO_DIR / "campaign-data" / "results")
    args = ap.parse_args(argv)
    plan = dict(PIVOT if args.pivot else CUBE)
    if args.assets or args.closures:
        plan = {a: tuple(args.closures or next(iter(plan.values()))) for a in (args.assets or plan)}
    for y in args.yaw:
        if y != "align":
            try:
                float(y)
            except ValueError:
                ap.error(f"--yaw {y}: give 'align' or a number (rad)")
    try:
        grasps = run(plan, args.seeds, args.yaw, args.out / "twin_pinch.json")
    except ValueError as e:
        ap.error(str(e))
    print(format_tables(grasps))
    print(f"written: {args.out / 'twin_pinch'}.json, .md")
    return grasps


if __name__ == "__main__":
    main()
