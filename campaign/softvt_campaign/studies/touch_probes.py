"""What touch carries (campaign step 5): linear probes on the rendered demos that predict the pad
force, the deformation ratio R_t and slip from the tactile stream alone, the wrist camera alone,
and both, scored on held-out demos.

    python -m softvt_campaign.studies.touch_probes --demos /root/softvt-demos --camera-size 84x84

Per frame of a demo (the observation after each step):

- inputs: ``tactile``, both fingers' GelSight image and depth map shrunk to 15 x 20 and their
  marker displacements (2,796 numbers); ``wrist``, the hand camera shrunk to 21 x 21 (1,323);
  ``both``, the two side by side;
- targets (from the evaluator stream, never an observation): the mean normal force of the two
  pads (N), R_t, and slip: the object's centroid moving relative to the TCP faster than
  :data:`SLIP_SPEED` while both pads press on it.

A ridge regression per input and target (closed form on standardised inputs, its strength
picked on a validation split of the training demos) is fitted on the first demos of each task and
scored on the rest (``--heldout-fraction``): R^2 of force and R_t over every frame and over the
frames in contact (where the magnitude is what is left to predict), and for slip the ROC AUC and
the balanced accuracy over the frames in contact. Linear on purpose: a small, honest measure of
what each stream makes readily available; a policy's CNN may extract more. Writes
``<out>/<suite>.json``, ``.md`` and ``.png``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from tqdm import tqdm

from mani_skill_softvt.data.demo_set import DemoSet
from mani_skill_softvt.data.images import resize_image
from mani_skill_softvt.data.trajectory import episode_digest, open_h5, rendering_current
from mani_skill_softvt.fileio import atomic_write, atomic_write_json
from mani_skill_softvt.contracts.observations import CAMERAS, MARKER_FIELDS, SIDES, TCP_POSE, camera_key, parse_image_size, tactile_key
from mani_skill_softvt.paths import DEMOS_DIR, REPO_DIR
from mani_skill_softvt.tasks.suites import NUM_TASKS, get_suite

SLIP_SPEED = 1e-3  # m/s: an object moving 0.05 mm per 50-ms step relative to the fingers slips
CONTACT_FORCE = 0.05  # N on each pad: both pads press on the object
CONTROL_DT = 0.05  # s per control step (20 Hz)
TACTILE_PROBE_SIZE = (15, 20)
WRIST_PROBE_SIZE = (21, 21)
DEPTH_SCALE_UM = 200.0
INPUTS = ("tactile", "wrist", "both")
LAMBDAS = (1e-2, 1e-1, 1.0, 10.0, 1e2, 1e3, 1e4)


# ------------------------------------------------------------------------------ pure functions

def slip_labels(centroids: np.ndarray, tcp: np.ndarray, contact: np.ndarray, dt: float = CONTROL_DT,
                speed: float = SLIP_SPEED) -> np.ndarray:
    """Per step (T,): the object's centroid moved relative to the TCP faster than ``speed``
    between states t and t+1 while both pads pressed on it (``contact`` (T,)); centroids and
    TCP positions are per state (T+1, 3)."""
    rel = np.diff(np.asarray(centroids, np.float64) - np.asarray(tcp, np.float64), axis=0) / dt
    return (np.linalg.norm(rel, axis=1) > speed) & np.asarray(contact, bool)


def ridge_fit(x: np.ndarray, y: np.ndarray, lam: float) -> tuple[np.ndarray, float]:
    """Weights and intercept of ridge regression on (N, D) ``x`` (centred inside), (N,) ``y``;
    the penalty is ``lam`` per sample."""
    return RidgeSolver(x).fit(y, lam)


class RidgeSolver:
    """Ridge regressions of several targets on one input matrix: the Gram matrix is formed once.

    The input stays as given (float32 for the demos' frames) and is read in row blocks, each
    centred in float64: a centred float64 copy of 1,000 demos' frames would take about 6 GB."""

    BLOCK = 8192  # rows per block

    def __init__(self, x: np.ndarray):
        self.x, self.n = x, len(x)
        self.mx = x.mean(0, dtype=np.float64)
        self.gram = np.zeros((x.shape[1], x.shape[1]))
        for xc in self._blocks():
            self.gram += xc.T @ xc

    def _blocks(self):
        for start in range(0, self.n, self.BLOCK):
            yield self.x[start:start + self.BLOCK].astype(np.float64) - self.mx

    def fit(self, y: np.ndarray, lam: float) -> tuple[np.ndarray, float]:
        return self.fits(y, (lam,))[lam]

    def fits(self, y: np.ndarray, lams) -> dict[float, tuple[np.ndarray, float]]:
        """(weights, intercept) for each penalty in ``lams``: one pass over the input for all."""
        my = float(y.mean())
        yc = np.asarray(y, np.float64) - my
        rhs = sum(xc.T @ yc[i * self.BLOCK:(i + 1) * self.BLOCK] for i, xc in enumerate(self._blocks()))
        out = {}
        for lam in lams:
            w = np.linalg.solve(self.gram + lam * self.n * np.eye(len(self.gram)), rhs)
            out[lam] = (w, my - float(self.mx @ w))
        return out


def r2(y: np.ndarray, pred: np.ndarray) -> float:
    """Coefficient of determination (1: perfect; 0: no better than the mean; negative: worse)."""
    ss = float(((y - y.mean()) ** 2).sum())
    return float("nan") if ss == 0 else 1.0 - float(((y - pred) ** 2).sum()) / ss


def roc_auc(labels: np.ndarray, score: np.ndarray) -> float:
    """Probability that a random positive scores above a random negative (ties count half)."""
    labels = np.asarray(labels, bool)
    pos, neg = score[labels], score[~labels]
    if len(pos) == 0 or len(neg) == 0:
        return float("nan")
    order = np.argsort(np.concatenate([pos, neg]), kind="mergesort")
    ranks = np.empty(len(order))
    values = np.concatenate([pos, neg])[order]
    # average ranks over ties
    _, first, counts = np.unique(values, return_index=True, return_counts=True)
    avg = first + (counts - 1) / 2.0
    ranks[order] = np.repeat(avg, counts) + 1
    return float((ranks[:len(pos)].sum() - len(pos) * (len(pos) + 1) / 2) / (len(pos) * len(neg)))


def balanced_accuracy(labels: np.ndarray, predicted: np.ndarray) -> float:
    labels, predicted = np.asarray(labels, bool), np.asarray(predicted, bool)
    if labels.all() or (~labels).all():
        return float("nan")
    return float(0.5 * ((predicted & labels).sum() / labels.sum() + (~predicted & ~labels).sum() / (~labels).sum()))


# ---------------------------------------------------------------------------- data from demos

def tactile_features(flat: dict, t: int) -> np.ndarray:
    parts = []
    for side in SIDES:
        rgb = resize_image(np.asarray(flat[tactile_key(side, "rgb")][t]), TACTILE_PROBE_SIZE).astype(np.float32) / 255
        depth = resize_image(np.asarray(flat[tactile_key(side, "depth")][t], np.float32), TACTILE_PROBE_SIZE)
        markers = np.asarray(flat[tactile_key(side, MARKER_FIELDS[1])][t], np.float32) - \
            np.asarray(flat[tactile_key(side, MARKER_FIELDS[0])][t], np.float32)
        parts += [rgb.ravel(), (depth / DEPTH_SCALE_UM).ravel(), markers.ravel()]
    return np.concatenate(parts)


def wrist_features(flat: dict, t: int) -> np.ndarray:
    return (resize_image(np.asarray(flat[camera_key(CAMERAS[1])][t]), WRIST_PROBE_SIZE).astype(np.float32) / 255).ravel()


def episode_frames(trajectory_group, rendered_group) -> dict[str, np.ndarray]:
    """Inputs and targets of the frames after each step of one demo."""
    ev = trajectory_group["evaluator"]
    obs = rendered_group["obs"]
    keys = [camera_key(CAMERAS[1])] + [tactile_key(s, f) for s in SIDES for f in ("rgb", "depth", *MARKER_FIELDS)]
    flat = {k: obs[k][()] for k in keys}
    pad_force = ev["pad_force"][()]  # (T, 2), after each step
    contact = (pad_force > CONTACT_FORCE).all(1)
    slip = slip_labels(ev["object_centroids"][()][:, 0], obs[TCP_POSE][()][:, :3], contact)
    steps = len(pad_force)
    frames = range(1, steps + 1)  # observation t+1 follows step t
    return {"tactile": np.stack([tactile_features(flat, t) for t in frames]),
            "wrist": np.stack([wrist_features(flat, t) for t in frames]),
            "force": pad_force.mean(1), "r_t": ev["deformation_ratio"][()][1:], "slip": slip, "contact": contact}


def load_frames(demos_root: Path, suite: str, tasks: list[int], camera_size, heldout_fraction: float) -> dict:
    """Every frame of the rendered demos, with a ``heldout`` flag (the last demos of each task) and
    the episode index (for the validation split). Only episodes whose rendering is current are
    read (a demo set still being rendered has fewer, an older one frames of another tactile model);
    ``skipped`` counts the others."""
    demo_set = DemoSet(demos_root, suite)
    sources = demo_set.rendered_sources(tasks, "rgb+tactile", camera_size)
    out: dict[str, list] = {}
    episode = skipped = 0
    with tqdm(total=len(sources), desc="read demos", unit="task") as bar:
        for src in sources:
            with open_h5(src.trajectory_h5) as ft, open_h5(src.rendered_h5) as fr:
                names = [k for k in sorted(ft.keys(), key=lambda k: int(k.split("_")[1]))
                         if k in fr and rendering_current(fr[k], episode_digest(ft[k]),
                                                          tactile_model=get_suite(suite).tactile_model)]
                skipped += len(ft.keys()) - len(names)
                if len(names) < 2:
                    raise ValueError(f"{src.rendered_h5}: {len(names)} rendered demos; probes need at least 2 a task "
                                     f"(demos render --camera-size ...)")
                n_train = len(names) - max(1, round(heldout_fraction * len(names)))
                for i, name in enumerate(names):
                    frames = episode_frames(ft[name], fr[name])
                    n = len(frames["force"])
                    frames["heldout"] = np.full(n, i >= n_train)
                    frames["episode"] = np.full(n, episode)
                    episode += 1
                    for k, v in frames.items():
                        out.setdefault(k, []).append(v)
            bar.update()
    return {**{k: np.concatenate(v) for k, v in out.items()}, "skipped": skipped}


# ------------------------------------------------------------------------------------- probing

class Probe:
    """Ridge probes of one input on a set of training frames: the strength is picked per target on
    the last fifth of the training episodes, then the probe is refitted on all of them."""

    def __init__(self, x: np.ndarray, episode: np.ndarray):
        cut = np.quantile(np.unique(episode), 0.8)
        self.fit_rows, self.val_rows = episode <= cut, episode > cut
        self.x_val = x[self.val_rows]
        self.part, self.full = RidgeSolver(x[self.fit_rows]), RidgeSolver(x)

    def fit(self, y: np.ndarray) -> tuple[np.ndarray, float, float]:
        """(weights, intercept, lambda) for the target ``y`` of the training frames."""
        fits = self.part.fits(y[self.fit_rows], LAMBDAS)

        def val_error(lam: float) -> float:
            w, b = fits[lam]
            return float(((self.x_val @ w + b - y[self.val_rows]) ** 2).mean())

        lam = min(LAMBDAS, key=val_error)
        w, b = self.full.fit(y, lam)
        return w, b, lam


def probe(data: dict, inputs: str) -> dict:
    x = data["wrist"] if inputs == "wrist" else data["tactile"] if inputs == "tactile" else \
        np.concatenate([data["tactile"], data["wrist"]], axis=1)
    train, test = ~data["heldout"], data["heldout"]
    mu, sd = x[train].mean(0), x[train].std(0) + 1e-6
    z = ((x - mu) / sd).astype(np.float32)  # the solver centres it in float64, block by block
    out = {}
    probe_all = Probe(z[train], data["episode"][train])
    contact = data["contact"][test]
    for target in ("force", "r_t"):
        y = data[target].astype(np.float64)
        w, b, lam = probe_all.fit(y[train])
        pred = z[test].astype(np.float64) @ w + b
        out[target] = {"r2_all": r2(y[test], pred), "r2_contact": r2(y[test][contact], pred[contact]), "lambda": lam}
    # Slip: among frames in contact only (out of contact there is nothing to slip).
    c_train, c_test = train & data["contact"], test & data["contact"]
    y = np.where(data["slip"], 1.0, -1.0)
    w, b, lam = Probe(z[c_train], data["episode"][c_train]).fit(y[c_train])
    score, train_score = z[c_test].astype(np.float64) @ w + b, z[c_train].astype(np.float64) @ w + b
    labels = data["slip"][c_test]
    # Call as many frames slipping as slipped in training.
    threshold = np.quantile(train_score, 1 - data["slip"][c_train].mean())
    out["slip"] = {"auc": roc_auc(labels, score), "balanced_accuracy": balanced_accuracy(labels, score > threshold),
                   "positives_heldout": int(labels.sum()), "frames_heldout": len(labels), "lambda": lam}
    return out


def run(demos_root: Path, suite: str, tasks: list[int], camera_size, heldout_fraction: float) -> dict:
    data = load_frames(demos_root, suite, tasks, camera_size, heldout_fraction)
    result = {"suite": suite, "tasks": tasks, "frames": len(data["force"]),
              "frames_heldout": int(data["heldout"].sum()), "episodes": int(data["episode"].max() + 1),
              "episodes_not_yet_rendered": int(data["skipped"]),
              "contact_share": float(data["contact"].mean()),
              "slip_share_in_contact": float(data["slip"][data["contact"]].mean()),
              "slip_speed_m_s": SLIP_SPEED, "probes": {}}
    for inputs in tqdm(INPUTS, desc="probes", unit="input"):
        result["probes"][inputs] = probe(data, inputs)
    return result


def format_result(result: dict) -> str:
    title = (f"{result['suite']}: {result['episodes']} demos, {result['frames']} frames "
             f"({result['frames_heldout']} held out); in contact {100 * result['contact_share']:.0f} % of frames, "
             f"slipping (> {1e3 * result['slip_speed_m_s']:.0f} mm/s) in {100 * result['slip_share_in_contact']:.1f} % "
             "of those")
    lines = [title, "",
             "| input | force R^2 (all) | force R^2 (contact) | R_t R^2 (all) | R_t R^2 (contact) | slip AUC | slip bal. acc. |",
             "|---|---|---|---|---|---|---|"]
    for inputs, p in result["probes"].items():
        lines.append(f"| {inputs} | {p['force']['r2_all']:.2f} | {p['force']['r2_contact']:.2f} | {p['r_t']['r2_all']:.2f} | "
                     f"{p['r_t']['r2_contact']:.2f} | {p['slip']['auc']:.2f} | {p['slip']['balanced_accuracy']:.2f} |")
    return "\n".join(lines)


def plot_result(result: dict, path: Path) -> None:
    measures = [("force", "r2_contact", "force R² (contact)"), ("r_t", "r2_contact", "R_t R² (contact)"),
                ("slip", "auc", "slip AUC")]
    fig = Figure(figsize=(6.5, 3.2))
    ax = fig.subplots()
    width = 0.25
    for i, inputs in enumerate(INPUTS):
        vals = [result["probes"][inputs][t][m] for t, m, _ in measures]
        ax.bar(np.arange(len(measures)) + (i - 1) * width, vals, width, label=inputs)
    ax.set_xticks(np.arange(len(measures)), [label for *_, label in measures])
    ax.axhline(0.5, color="0.6", lw=0.8, ls=":")  # chance AUC
    ax.set_ylim(min(0.0, ax.get_ylim()[0]), 1.0)
    ax.set_title(f"linear probes on held-out demos ({result['suite']})")
    ax.legend(fontsize=8, loc="lower center", ncol=3, framealpha=0.9)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=120))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m softvt_campaign.studies.touch_probes", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--demos", type=Path, default=DEMOS_DIR)
    ap.add_argument("--suite", default="object_soft")
    ap.add_argument("--tasks", nargs="+", type=int, default=list(range(NUM_TASKS)))
    ap.add_argument("--camera-size", default="84x84", help="which rendering (as passed to demos render)")
    ap.add_argument("--heldout-fraction", type=float, default=0.2, help="the last demos of each task, scored on")
    ap.add_argument("--out", type=Path, default=REPO_DIR / "campaign-data" / "probes")
    args = ap.parse_args(argv)
    if not 0 < args.heldout_fraction < 1:
        ap.error(f"--heldout-fraction {args.heldout_fraction}: give a fraction in (0, 1)")
    try:
        result = run(args.demos, args.suite, args.tasks, parse_image_size(args.camera_size, "--camera-size"),
                     args.heldout_fraction)
    except (FileNotFoundError, ValueError) as e:
        ap.error(str(e))
    table = format_result(result)
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out / f"{args.suite}.json", result)
    atomic_write(args.out / f"{args.suite}.md", lambda tmp: tmp.write_text(table + "\n"))
    plot_result(result, args.out / f"{args.suite}.png")
    print(table)
    print(f"written: {args.out / args.suite}.json, .md, .png")
    return result


if __name__ == "__main__":
    main()
