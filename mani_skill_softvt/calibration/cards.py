"""Calibration cards: one JSON per deformable asset in ``calibration/`` (written atomically)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from .. import __version__
from ..io import atomic_write_json
from ..paths import CALIBRATION_DIR
from . import protocol as P
from .stats import gripper_envelope

CARD_FIELDS = ("asset_id", "g_min", "g_max", "tau_o", "percentile", "aperture_g_min_mm", "aperture_g_max_mm",
               "span_mm", "records")


def make_card(asset_id: str, records: list[dict], percentile: float, closures, repeats: int) -> dict:
    env = gripper_envelope(records, percentile)
    return {
        "asset_id": asset_id,
        **env,
        "tau_o_percent_of_diagonal": 100.0 * env["tau_o"],  # D is already normalised by the diagonal
        "slip_criterion": {
            "measure": "displacement of the object's centroid in the TCP frame between the first and last "
                       "control step of the 2 s hold",
            "threshold_mm": 1e3 * P.SLIP_THRESHOLD,
            "also_required": f"object's lowest node >= {1e3 * P.LIFT_THRESHOLD:.0f} mm above the table at the end of the hold",
        },
        "protocol": {"closures": [float(g) for g in closures], "repeats": int(repeats), "steps": dict(P.STEPS),
                     "jitter_xy_mm": 1e3 * P.JITTER_XY, "jitter_yaw_deg": float(P.JITTER_YAW * 180 / 3.141592653589793),
                     "env": "SoftGraspLift-v1", "control_mode": "pd_ee_pose"},
        "package_version": __version__,
        "records": records,
    }


def card_path(asset_id: str, directory: Path = CALIBRATION_DIR) -> Path:
    return Path(directory) / f"{asset_id}.json"


def write_card(card: dict, directory: Path = CALIBRATION_DIR) -> Path:
    path = card_path(card["asset_id"], directory)
    atomic_write_json(path, card)
    return path


def load_calibration(asset_id: str, directory: Path = CALIBRATION_DIR) -> dict:
    """A calibration card; clear errors when it is missing or malformed."""
    path = card_path(asset_id, directory)
    if not path.exists():
        raise FileNotFoundError(f"no calibration card for '{asset_id}' at {path}; run "
                                f"`python -m mani_skill_softvt.calibrate --assets {asset_id}`")
    try:
        card = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"calibration card {path} is not valid JSON ({e}); re-run the calibration") from e
    missing = [f for f in CARD_FIELDS if f not in card]
    if missing:
        raise ValueError(f"calibration card {path} lacks {missing}; re-run the calibration")
    return card


def card_hash(card: dict) -> str:
    """Content hash of a card (for evaluation receipts)."""
    return hashlib.sha256(json.dumps(card, sort_keys=True).encode()).hexdigest()


def rescore(card: dict, percentile: float) -> dict:
    """The envelope at another percentile, from the card's sweep records alone."""
    return gripper_envelope(card["records"], percentile)
