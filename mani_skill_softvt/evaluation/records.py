"""The evaluation record on disk: its hash, its verification, and the one place older formats are read.

A record is one JSON line per episode (:mod:`.runner` writes them). ``record_sha256`` is a
hash of everything but the wall time, so an edited or corrupt line is refused with its file and
line. Records written by earlier versions lack fields added since; :func:`migrate_record` fills
them in as those versions meant them, once, when a file is read, so that no reader branches on
a record's age.
"""

from __future__ import annotations

from pathlib import Path

from ..fileio import read_jsonl_lines
from ..provenance import UNHASHED, record_hash, seal  # noqa: F401  (the seal: provenance/)
from .run import recorded_camera_size


class RecordIntegrityError(ValueError):
    """A stored record that is not what the evaluator wrote (edited, corrupt, or not a record)."""


def migrate_record(record: dict) -> dict:
    """A stored record in today's format (a new dict; the stored one is what its hash covers).

    The fields added since the first records are filled in with what the records before them meant:
    the rows of :data:`~mani_skill_softvt.provenance.UPGRADES` for ``evaluation record`` whose ``where``
    is this function (camera_size, tactile_model, collapsed_steps, dsr_success).
    """
    out = dict(record)
    obs_mode = out.get("obs_mode")
    out.setdefault("camera_size", recorded_camera_size(obs_mode, None))
    out.setdefault("tactile_model", 1 if "tactile" in str(obs_mode) else None)
    out.setdefault("collapsed_steps", 0)
    if "dsr_success" not in out:
        r_max = out.get("r_max")
        out["dsr_success"] = bool(out.get("success")) and r_max is not None and float(r_max) <= 1.0
    return out


def read_records(path: Path) -> list[dict]:
    """The records of an evaluation log, each verified against its ``record_sha256``, in today's
    format (:func:`migrate_record`).

    A torn last line (a writer killed mid-line) is dropped, as :func:`~mani_skill_softvt.fileio.read_jsonl_lines`
    does; any other bad line raises :class:`RecordIntegrityError` naming the file and line.
    """
    out = []
    for lineno, rec in read_jsonl_lines(path):
        where = f"{path}:{lineno}"
        if not isinstance(rec, dict) or "record_sha256" not in rec:
            raise RecordIntegrityError(f"{where}: not an evaluation record (no record_sha256); "
                                       "remove the line, or evaluate into another --out")
        if rec["record_sha256"] != record_hash(rec):
            raise RecordIntegrityError(f"{where}: the record does not match its record_sha256 (edited or corrupt); "
                                       "remove the line to re-run that episode")
        out.append(migrate_record(rec))
    return out
