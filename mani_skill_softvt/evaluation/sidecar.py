"""What is known of where records were made when they do not say it themselves: the provenance sidecar.

Records are sealed (``record_sha256``), so a record made before the stack, the CPU or the numerics
were kept cannot be mended in place. A directory of records may hold ``provenance.json``: per
records file, what is known of the machine, stack and numerics its records ran on, and from what
evidence (a commit, a session's notes, a measured reproduction). The reports read it beside the
records' own ``receipt.stack`` and ``receipt.numerics``, and say when a table crosses machines;
``evaluate --reproduce`` reads it to replay a file under the numerics its machine had.
"""

from __future__ import annotations

from pathlib import Path

from ..fileio import read_json
from ..provenance.numerics import PINNED, machine_kind, numerics_of, pinned_in_full

PROVENANCE_FILE = "provenance.json"


def sidecar(records_path: Path) -> dict | None:
    """The sidecar entry of a records file (None where its directory has no sidecar or no entry)."""
    path = Path(records_path)
    side = path.parent / PROVENANCE_FILE
    if not side.is_file():
        return None
    entries = read_json(side).get("files", {})
    return entries.get(path.name)


def machine(records: list[dict], entry: dict | None = None) -> str:
    """The machine a file's records ran on, as they name it (CPU model, and where kept its
    instruction-set flags), else as the sidecar ``entry`` says (marked ``per sidecar``), else
    ``unrecorded``. Several machines in one file are all named."""
    named = set()
    for r in records:
        stack = (r.get("receipt") or {}).get("stack") or {}
        if stack.get("cpu"):
            cpu, flags = machine_kind(stack)  # the CPU's own flags, not what the numerics capped
            named.add(f"{cpu}{' (' + ' '.join(flags) + ')' if flags else ''}")
    if named:
        return "; ".join(sorted(named))
    if entry and entry.get("cpu"):
        return f"{entry['cpu']} (per sidecar)"
    return "unrecorded"


def numerics(records: list[dict], entry: dict | None = None) -> str:
    """The numerics a file's records name (today's name marked ``not in effect`` where a part was released
    or a library loaded before the pins), else the sidecar's (``per sidecar``), else what the machine a
    record names ran natively before the pins (``before the pins``; ``native`` where unknown)."""
    labels = set()
    for r in records:
        if (r.get("receipt") or {}).get("numerics"):
            # numerics_of: records of the earlier pins carry today's name; their MKL variable or lack of parts tells them apart.
            name = numerics_of(r)
            labels.add(f"{name} (not in effect)" if name == PINNED and not pinned_in_full(r) else name)
        elif entry and entry.get("numerics"):
            labels.add(f"{entry['numerics']} (per sidecar)")
        else:
            labels.add(f"{numerics_of(r)} (before the pins)")
    if labels:
        return "; ".join(sorted(labels))
    if entry and entry.get("numerics"):
        return f"{entry['numerics']} (per sidecar)"
    return "native (before the pins)"


def crossing_note(rows: list[tuple[str, str]]) -> str | None:
    """What a table over records files may compare, given each file's (:func:`machine`, :func:`numerics`):
    None where they share one machine kind and one numerics. Under today's full pins a record keeps
    its bits on any x86-64 machine (its goldens passed on an Intel Xeon and an AVX2-only AMD EPYC;
    docs/install.md), so crossing machines leaves records comparable. Under anything else the same
    episode may round differently on another CPU model or instruction set (the flags are part of
    the kind then), and only rates compare; so too where a machine is not recorded."""
    def label(text: str) -> str:
        return text.removesuffix(" (per sidecar)").removesuffix(" (before the pins)")

    models = {label(one).split(" (")[0] for m, _ in rows for one in m.split("; ")}
    kinds = {label(one) for m, _ in rows for one in m.split("; ")}
    names = {label(one) for _, x in rows for one in x.split("; ")}
    if len(names) > 1:
        machines = f"machines ({'; '.join(sorted(kinds))}) and " if len(kinds) > 1 else ""
        return (f"These rows cross {machines}numerics ({'; '.join(sorted(names))}): compare their rates, not "
                "their records (docs/install.md, numerics).")
    if names == {PINNED}:
        return None if len(models) < 2 else (
            f"These rows cross machines ({'; '.join(sorted(models))}) under the full pins ({PINNED}), which give "
            "the same bits on any x86-64 machine: their records compare too (docs/install.md, numerics).")
    if "unrecorded" in kinds and len(rows) > 1:
        return (f"Not every file of these rows names its machine ({'; '.join(sorted(kinds))}), under numerics "
                f"({next(iter(names))}) whose bits depend on the CPU: compare their rates, not their records "
                "(docs/install.md, numerics).")
    if len(kinds) < 2:
        return None
    return (f"These rows cross machines ({'; '.join(sorted(kinds))}) under numerics ({next(iter(names))}) whose bits "
            "depend on the CPU: compare their rates, not their records (docs/install.md, numerics).")
