"""Calibration cards: one JSON per deformable asset in ``calibration-data/`` (written atomically)."""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from ..version import __version__
from ..fileio import atomic_write_json, read_json
from ..paths import CALIBRATION_DIR, missing_data_hint
from ..physics.config import DEFAULT_PHYSICS, PhysicsConfig
from ..physics.config import physics_signature, signature_mismatch
from . import protocol as P
from .stats import gripper_envelope

CARD_FIELDS = ("asset_id", "g_min", "g_max", "tau_o", "percentile", "aperture_g_min_mm", "aperture_g_max_mm",
               "span_mm", "records")
_RECALIBRATE = "re-run the calibration (python -m mani_skill_softvt.calibrate --assets <asset>)"


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
        # The sweep refused trials from other physics, so the records share one signature (the env's
        # they ran in): kept once here, and checked whenever the card is loaded.
        "physics": next((r["physics"] for r in records if "physics" in r), physics_signature()),
        "records": [{k: v for k, v in r.items() if k != "physics"} for r in records],
    }


def card_path(asset_id: str, directory: Path = CALIBRATION_DIR) -> Path:
    return Path(directory) / f"{asset_id}.json"


def write_card(card: dict, directory: Path = CALIBRATION_DIR) -> Path:
    path = card_path(card["asset_id"], directory)
    atomic_write_json(path, card)
    return path


@dataclass(frozen=True)
class CalibrationCard:
    """An asset's calibration (paper section 3.5): gripper envelope, tolerance tau_o, sweep records.

    ``data`` is the card's JSON as written (its hash goes into evaluation receipts); the typed
    fields are read from it and validated when the card is loaded.
    """

    asset_id: str
    g_min: float  # loosest closure that holds without slip in every repeat
    g_max: float  # tightest closure whose peaks stay within tau_o
    tau_o: float  # deformation tolerance: the percentile of peak D over the stable grasps
    percentile: float
    aperture_g_min_mm: float
    aperture_g_max_mm: float
    span_mm: float
    records: tuple  # every sweep trial (dicts), so another percentile is a re-aggregation
    data: dict = field(repr=False, compare=False)

    @classmethod
    def from_dict(cls, data: dict, source: str = "calibration card") -> "CalibrationCard":
        """Typed, validated card; errors name ``source`` (the file) and what to do."""
        missing = [f for f in CARD_FIELDS if f not in data]
        if missing:
            raise ValueError(f"{source} lacks {missing}; {_RECALIBRATE}")
        values = {}
        for key in CARD_FIELDS[1:-1]:
            v = data[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{source}: {key} must be a finite number, got {v!r}; {_RECALIBRATE}")
            values[key] = float(v)
        if values["g_min"] == values["g_max"]:
            # A sweep too coarse to resolve the envelope: only one of its closures both holds and
            # stays within tau_o. The expert would always grasp at that one closure.
            raise ValueError(f"{source}: the envelope is the single closure {values['g_min']} (g_min = g_max): "
                             "the sweep is too coarse to resolve it; add closures on both sides of it "
                             "(calibrate --closures ...) and recalibrate")
        if not 0.0 < values["g_min"] < values["g_max"] <= 1.0:
            raise ValueError(f"{source}: the envelope must satisfy 0 < g_min < g_max <= 1, got g_min "
                             f"{values['g_min']}, g_max {values['g_max']}; {_RECALIBRATE}")
        if not values["tau_o"] > 0.0:
            raise ValueError(f"{source}: tau_o must be positive, got {values['tau_o']}; {_RECALIBRATE}")
        if not isinstance(data["records"], list):
            raise ValueError(f"{source}: records must be a list of sweep trials; {_RECALIBRATE}")
        return cls(asset_id=str(data["asset_id"]), records=tuple(data["records"]), data=data, **values)

    @property
    def sha256(self) -> str:
        """Content hash of the card as written (for evaluation receipts)."""
        return hashlib.sha256(json.dumps(self.data, sort_keys=True).encode()).hexdigest()

    def at_percentile(self, percentile: float) -> dict:
        """The envelope at another percentile, from the card's sweep records alone."""
        return gripper_envelope(list(self.records), percentile)


def load_calibration_card(asset_id: str, directory: Path = CALIBRATION_DIR, check_physics: bool = True,
                          physics: PhysicsConfig = DEFAULT_PHYSICS) -> CalibrationCard:
    """The calibration card of a deformable asset; clear errors when it is missing or malformed.

    With ``check_physics`` (the default) a card calibrated under other physics than ``physics`` (the
    env's; default the package's) is refused: its envelope and tau_o would not describe the objects
    being simulated. Benchmarks that vary the physics on purpose pass ``False``.
    """
    path = card_path(asset_id, directory)
    if not path.exists():
        hint = missing_data_hint(directory, "SOFTVT_CALIBRATION_DIR", "calibration",
                                 f"python -m mani_skill_softvt.calibrate --assets {asset_id}")
        raise FileNotFoundError(f"no calibration card for '{asset_id}' at {path}; {hint}")
    try:
        data = read_json(path)
    except ValueError as e:
        raise ValueError(f"calibration card {e}; or {_RECALIBRATE}") from None
    card = CalibrationCard.from_dict(data, f"calibration card {path}")
    if card.asset_id != asset_id:
        raise ValueError(f"calibration card {path} describes '{card.asset_id}', expected '{asset_id}'; {_RECALIBRATE}")
    stale = signature_mismatch(data.get("physics"), physics) if check_physics else []
    if stale:
        raise ValueError(f"calibration card {path} was made under other physics ({'; '.join(stale)}); its envelope "
                         f"and tau_o do not hold for the objects simulated now: re-run the calibration "
                         f"(python -m mani_skill_softvt.calibrate --restart --assets {asset_id})")
    return card
