"""What the commands share in reading their arguments."""

from __future__ import annotations

import sys
from pathlib import Path

from ..provenance import moved_data_path


def existing_path(path: Path, flag: str) -> Path:
    """``path`` as given where it exists; else, where it names a file in a data folder's old spelling
    (``baselines/results/...``, ``demos/...``: provenance.RENAMED_DATA_FOLDERS) that exists under the
    folder's new name, that file, with a note on stderr; else ``path`` unchanged, for the command's own
    'does not exist' error."""
    path = Path(path)
    moved = moved_data_path(path.as_posix())
    if moved is not None:
        print(f"note: {flag} {path}: that folder was renamed; reading {moved}", file=sys.stderr)
        return Path(moved)
    return path
