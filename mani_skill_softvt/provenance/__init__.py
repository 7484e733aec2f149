"""Provenance: what this package's files are stamped with, and what an older file lacks.

One place for every version marker a file carries, the seal of an evaluation record, the
comparison of a recorded physics signature, and :data:`UPGRADES`, the table of what a file from
an earlier version lacks, how it is read, and what to do about it. The code that reads a file
takes its markers and its remedies from here; the markers' histories are written here once.

Beside it in this package: :mod:`.numerics`, the CPU dispatch every library is pinned to as the
package loads (and how a record made under earlier numerics is read), and :mod:`.stack`, the
software stack and machine a record names. Computed with its config, compared here: the physics
signature is :meth:`~mani_skill_softvt.physics.config.PhysicsConfig.signature` (the settings of an env,
with :data:`EE_ORIENTATION_AXIS_ANGLE`). What is known of sealed records that predate the stack is the
sidecar of :mod:`mani_skill_softvt.evaluation.sidecar`. The campaign's own markers
(``FEATURES_VERSION``, ``CACHE_FORMAT``) live with its data cache; their rows are in :data:`UPGRADES`.

This module imports nothing of the package (nor does :mod:`.numerics`): everything that writes or
reads a file may import it, and the numerics are pinned from here before any library loads.
"""

from __future__ import annotations

import hashlib
import json
import posixpath
from dataclasses import dataclass
from pathlib import Path

# ------------------------------------------------------------------ renamed data folders

# The committed data's top-level folders took names no Python package can have ('-' cannot be
# imported), so that none is taken for code: old spelling -> new. A path given in an old spelling is
# read as the same file under the new name. The sealed records name their policy file by the path it
# had when they were made (``baselines/policies/...``); they stay as sealed, and what compares runs
# (resume, reproduce, record_differences) compares those paths through this map.
RENAMED_DATA_FOLDERS = {
    "assets/": "asset-data/",
    "calibration/": "calibration-data/",
    "demos/": "demo-data/",
    "baselines/results/": "campaign-data/results/",
    "baselines/search/": "campaign-data/search/",
    "baselines/probes/": "campaign-data/probes/",
    "baselines/policies/": "campaign-data/policies/",
}


def current_data_path(path) -> str | None:
    """``path`` (relative, '/'-separated, optionally starting with './') with a renamed data folder's
    old spelling replaced by today's, or None where it starts with no renamed folder."""
    text = str(path).replace("\\", "/")
    text = text[2:] if text.startswith("./") else text
    for old, new in RENAMED_DATA_FOLDERS.items():
        if text.startswith(old):
            return new + text[len(old):]
    return None


def today_data_path(path):
    """``path`` as spelled today: its renamed folder's new name, else ``path`` itself (any value)."""
    return (current_data_path(path) or path) if isinstance(path, str) else path


def same_data_path(a, b) -> bool:
    """Whether ``a`` and ``b`` name one file, either in a renamed folder's old spelling or its new one
    (two records of one run, one made before the rename), however the relative path is written
    (``./x``, ``x``, ``a/../x``); anything that is not a string compares as it is."""
    return _spelling(a) == _spelling(b)


def _spelling(path):
    """``path`` as spelled today, normalised ('/'-separated, no ``.`` or ``..`` parts); any other value as it is."""
    if not isinstance(path, str) or not path or "://" in path:  # not a file path (a ws:// policy, none)
        return today_data_path(path)
    return today_data_path(posixpath.normpath(path.replace("\\", "/")))


def moved_data_path(path) -> str | None:
    """Where a file named in a renamed folder's old spelling lies now: the new spelling if ``path``
    does not exist and that one does, else None (the path is read as it is)."""
    moved = current_data_path(path)
    return moved if moved is not None and not Path(path).exists() and Path(moved).exists() else None


# ------------------------------------------------------------------ version markers

# The gripper actions' encoding, recorded in every trajectory file's env kwargs and in a demo set's
# manifest (``gripper_action_version``). 1 (files without it): the closure in [0, 1] in every mode;
# 2: ManiSkill's normalised action in [-1, 1] (1 open) in the joint and delta modes, the closure in
# pd_ee_pose (the paper's mode, whose files never changed).
GRIPPER_ACTION_VERSION = 2
UPGRADE_COMMAND = "python -m mani_skill_softvt.integrations.maniskill.replay --upgrade-gripper"
GRIPPER_ACTION_VERSIONS = {  # why an older version is refused; {path}: the file
    1: "its joint- or delta-mode gripper actions are closures in [0, 1] (written before mani_skill_softvt used "
       "ManiSkill's normalised gripper action in [-1, 1] in those modes); convert the file in place with "
       f"`{UPGRADE_COMMAND} {{path}}`, then run this again",
}

# The tactile model. Renderings, baselines trained on them and evaluation records carry it
# (``tactile_model``), so that frames of one model are never mixed with another's (data saved
# without it is 1). 1: FOTS-style dilation (the slope of the blurred indentation); 2: the gel's
# outward flow; 3: a rigid twin is touched on the hull PhysX collides, not its tet boundary (which
# sat outside the hull: the whole pad read as pressed). Soft objects' frames did not change from 2
# to 3, so a soft scene's frames keep 2 and what was rendered or trained on them stays valid.
TACTILE_MODEL_VERSION = 3
TACTILE_SOFT_MODEL_VERSION = 2  # the last version that changed how an FEM surface is rendered

# What a rendering holds for the same states (cameras, shaders, observation keys), recorded per
# rendered episode (``render_version``; absent: 1). Bump it to have older renderings rendered again.
RENDER_VERSION = 1

# How the hand's orientation in a pd_ee_pose action is read: 1.0 the axis-angle the paper means
# (tasks.robot.AxisAnglePoseController). Not a physical setting: a history marker in the physics
# signature. Cards and demos made while ManiSkill's controller read it as XYZ Euler angles (a
# scripted grasp at 20 deg of yaw then came down tilted by ~30 deg) lack it, and are refused as
# made under other physics.
EE_ORIENTATION_AXIS_ANGLE = 1.0

# ------------------------------------------------------------------ the seal of a record

UNHASHED = ("record_sha256", "wall_s")  # wall time differs run to run; everything else must not


def record_hash(record: dict) -> str:
    """SHA-256 of an evaluation record without its hash and wall time (canonical JSON)."""
    body = {k: v for k, v in record.items() if k not in UNHASHED}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def seal(record: dict) -> dict:
    """The record with its ``record_sha256``."""
    record["record_sha256"] = record_hash(record)
    return record


# ------------------------------------------------------------------ the physics signature

def signature_differences(recorded, now: dict) -> list[str]:
    """Human-readable differences between a recorded physics signature and ``now``."""
    if not isinstance(recorded, dict):
        return ["no physics signature recorded (made before signatures existed)"]
    return [f"{k}: recorded {recorded.get(k)!r}, now {v!r}" for k, v in now.items() if recorded.get(k) != v]


# ------------------------------------------------------------------ what older files lack

@dataclass(frozen=True)
class Upgrade:
    """One thing a file from an earlier version lacks: which file (``file``), what (``lacks``), how
    this version reads such a file (``read_as``: a default, or refused), what to do (``remedy``),
    and where the code that does it lives (``where``, module:function, checked by the tests)."""

    file: str
    lacks: str
    read_as: str
    remedy: str
    where: str


REGENERATE_DEMOS = "record the demos again: python -m mani_skill_softvt.demos generate (it records the seeds the QC logs list)"
RERENDER = "render again: python -m mani_skill_softvt.demos render (it renders what is not current)"
RECALIBRATE = "calibrate again: python -m mani_skill_softvt.calibrate --restart --assets ASSET"

UPGRADES = (
    # Evaluation records: sealed, so never rewritten; filled in as they are read.
    Upgrade("evaluation record", "camera_size", "the native 224x224 cameras (none in a state obs mode)", "none needed",
            "mani_skill_softvt.evaluation.records:migrate_record"),
    Upgrade("evaluation record", "tactile_model", "1 in a +tactile obs mode (none without); so never resumed by "
            "today's runs, whose frames are another model", "none needed", "mani_skill_softvt.evaluation.records:migrate_record"),
    Upgrade("evaluation record", "collapsed_steps", "0 (a collapsed tet then ended the episode as sim_unstable)",
            "none needed", "mani_skill_softvt.evaluation.records:migrate_record"),
    Upgrade("evaluation record", "dsr_success", "success with R_max <= 1", "none needed",
            "mani_skill_softvt.evaluation.records:migrate_record"),
    Upgrade("evaluation record", "policy_sha256", "belongs to the run of the file it names", "none needed",
            "mani_skill_softvt.evaluation.runner:is_run_record"),
    Upgrade("evaluation record", "instructed_instance, other_in_target, instance_displacement (Spatial)",
            "not compared on reproduction; no instance outcome", "none needed",
            "mani_skill_softvt.evaluation.metrics:instance_outcomes"),
    Upgrade("evaluation record", "receipt.numerics", "the sidecar's numerics, else the CPU's legacy numerics, else "
            "native; replayed so", "a provenance.json sidecar beside the records",
            "mani_skill_softvt.provenance.numerics:numerics_of"),
    Upgrade("evaluation record", "receipt.numerics.parts: vml", "the pins before 2026-12-06, with VML's own kernel "
            "detection (vml-detect); replayed so, a policy's on its CPU vendor", "none needed",
            "mani_skill_softvt.provenance.numerics:numerics_of"),
    Upgrade("evaluation record", "receipt.stack (or keys of it)", "unrecorded: not a difference on reproduction",
            "a provenance.json sidecar beside the records", "mani_skill_softvt.provenance.stack:stack_differences"),
    # Demonstration files.
    Upgrade("trajectory .json", "gripper_action_version (1)", "refused in the joint and delta modes",
            f"convert in place: {UPGRADE_COMMAND} FILE.h5", "mani_skill_softvt.data.trajectory:gripper_action_problem"),
    Upgrade("demo manifest.json", "gripper_action_version (1)", "refused in the joint and delta modes",
            f"convert each task<k>.h5 with {UPGRADE_COMMAND} and set the manifest's version",
            "mani_skill_softvt.demonstrations.generate:generate"),
    Upgrade("demo manifest.json", "physics (or a key of it)", "refused: made under other physics",
            "generate into another --out", "mani_skill_softvt.demonstrations.generate:generate"),
    Upgrade("demo manifest.json", "numerics", "accepted with a note: recorded before the pins",
            "none needed (new episodes run under today's numerics)", "mani_skill_softvt.demonstrations.generate:generate"),
    Upgrade("trajectory .h5", "traj_<i> groups", "refused as corrupt", REGENERATE_DEMOS,
            "mani_skill_softvt.data.trajectory:read_episode"),
    Upgrade("trajectory .h5 (rigid twins)", "env_states/contact_wrenches", "refused for touch: a restored twin "
            "would show a blank gel", REGENERATE_DEMOS, "mani_skill_softvt.data.trajectory:holds_twin_contact"),
    Upgrade("env state (rigid twins)", "soft (FEM values)", "refused: recorded before the twins became rigid",
            REGENERATE_DEMOS, "mani_skill_softvt.tasks.objects:RigidTwins"),
    Upgrade("rendering .h5", "tactile_model", "1, so not current for today's frames", RERENDER,
            "mani_skill_softvt.data.trajectory:tactile_model_of"),
    Upgrade("rendering .h5", "render_version, states_sha256, the tactile depth map", "not current", RERENDER,
            "mani_skill_softvt.data.trajectory:rendering_current"),
    # Calibration.
    Upgrade("calibration card", "physics (or EE_ORIENTATION_AXIS_ANGLE)", "refused: made under other physics",
            RECALIBRATE, "mani_skill_softvt.calibration.cards:load_calibration_card"),
    Upgrade("calibration sweep log", "physics of a trial", "refused: trials under other physics", RECALIBRATE,
            "mani_skill_softvt.expert.calibration_trials:sweep_asset"),
    # The campaign's policy files and training caches (campaign/softvt_campaign: it reads them).
    Upgrade("policy file (.pt)", "tactile_model", "1: a VT policy is refused (today's frames are model 2 on the "
            "soft suites, 3 on the rigid)", "re-render the demos and train again (docs/baselines.md)",
            "softvt_campaign.baselines.agent:read_policy_file"),
    Upgrade("policy file (.pt)", "camera_render_size", "trained on the native 224x224 renderings", "none needed",
            "softvt_campaign.baselines.agent:camera_render_size"),
    Upgrade("policy file (.pt)", "config.precision", "fp32, the reference precision", "none needed",
            "softvt_campaign.baselines.config:DPConfig"),
    Upgrade("training checkpoint", "bf16_product_steps", "every step of a bf16 run trained with the native "
            "bfloat16 kernels (there was no other kind)", "none needed", "softvt_campaign.baselines.train:Training"),
    Upgrade("training data cache", "today's CACHE_FORMAT and FEATURES_VERSION in its key", "not current: built "
            "again from the renderings", "none needed (the next training rebuilds it)",
            "softvt_campaign.baselines.dataset:cache_key"),
    Upgrade("twin-pinch grasps .json", "tactile_model", "2, so refused beside today's twins' model (3)", "move it away "
            "to re-run", "softvt_campaign.studies.twin_pinch:run"),
    # Paths.
    Upgrade("a path given to a command", "the data folders' new names (assets/, calibration/, demos/, "
            "baselines/results/ ...)", "the same file under the new name, with a note", "none needed",
            "mani_skill_softvt.cli.arguments:existing_path"),
)


def upgrades_of(file: str) -> list[Upgrade]:
    """The rows of :data:`UPGRADES` for one kind of file."""
    return [u for u in UPGRADES if u.file == file]
