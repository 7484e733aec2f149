"""Atomic file writes: a reader (or a resumed run) never sees a half-written file."""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable


def atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it over ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix or ".tmp", dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file normal permissions
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_json(path: Path, data) -> None:
    atomic_write(path, lambda p: p.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n"))


def write_page(out_dir: Path, stem: str, text: str, data) -> Path:
    """A study's page: ``<stem>.md`` (the markdown ``text``) and ``<stem>.json`` (``data``), each
    written atomically; returns the markdown's path."""
    md = Path(out_dir) / f"{stem}.md"
    atomic_write(md, lambda p: p.write_text(text))
    atomic_write_json(Path(out_dir) / f"{stem}.json", data)
    return md


class CorruptLogError(ValueError):
    """A line of a JSONL log that is not JSON and is not a torn last line."""


def read_json(path: Path) -> dict:
    """A JSON object from ``path``; a file that does not parse or is not an object raises naming it."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e}); repair or remove it, then re-run") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object, got {type(data).__name__}; repair or remove it, then re-run")
    return data


@contextmanager
def file_lock(path: Path):
    """Hold an exclusive ``flock`` on ``path`` (created if missing), waiting for another holder;
    the kernel releases it when its holder dies, so a killed process leaves no stale lock."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def append_jsonl(path: Path, record: dict) -> None:
    """Append one record as a line and flush it to disk (resumable logs)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # A writer killed mid-line leaves a torn last line: cut it off first, so that it neither
    # glues onto the new record nor stays behind as a corrupt line in the middle of the log.
    with open(path, "ab") as f:
        # Exclusive while it checks the tail and writes: two processes logging to one file (the
        # recipe search's parallel runs) must not take each other's half-written line for torn.
        fcntl.flock(f, fcntl.LOCK_EX)
        size = f.seek(0, os.SEEK_END)
        if size and _last_byte(path) != b"\n":
            f.truncate(_torn_line_start(path))
        f.write((json.dumps(record, sort_keys=True) + "\n").encode())
        f.flush()
        os.fsync(f.fileno())


def _last_byte(path: Path) -> bytes:
    with open(path, "rb") as f:
        f.seek(-1, os.SEEK_END)
        return f.read(1)


def _torn_line_start(path: Path) -> int:
    """Offset just past the last newline (0 if none): where a torn last line begins."""
    data = Path(path).read_bytes()
    return data.rfind(b"\n") + 1


def read_jsonl_lines(path: Path) -> list[tuple[int, object]]:
    """(line number, value) of each line of a JSONL log; [] if the file does not exist.

    A last line without its newline that does not parse is a record torn by a killed writer: it
    is dropped (its episode or trial simply runs again). Any other line that does not parse is
    corruption and raises :class:`CorruptLogError` naming the file and line.
    """
    path = Path(path)
    if not path.exists():
        return []
    text = path.read_text()
    lines = text.split("\n")
    complete = lines[:-1]  # every line that ended with a newline; lines[-1] is "" or a torn tail
    out = []
    for i, line in enumerate(complete, start=1):
        try:
            out.append((i, json.loads(line)))
        except json.JSONDecodeError as e:
            raise CorruptLogError(f"{path}:{i}: not a JSON record ({e.msg}); the file is corrupt: "
                                  "remove or repair that line, then re-run") from None
    if lines[-1]:
        try:
            out.append((len(lines), json.loads(lines[-1])))
        except json.JSONDecodeError:
            pass  # torn by a killed writer
    return out


def read_jsonl(path: Path) -> list[dict]:
    """Records of a JSONL log (see :func:`read_jsonl_lines`: a torn last line is dropped, a
    corrupt line elsewhere raises with its file and line)."""
    return [rec for _, rec in read_jsonl_lines(path)]


def file_sha256(path: Path) -> str:
    """SHA-256 of a file's bytes (a policy file's identity in its records)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()
