"""Export a trained baseline for the repository: its weights in float16, at most 20 MiB.

    python -m softvt_campaign.baselines.export RUN/policy.pt campaign-data/policies/vo-c-cpu.pt --if-changed

The exported file is a ``policy.pt`` like the one training writes (``evaluate --policy`` loads
it, and the evaluator names its records after the file: ``object_soft_id_vo-c-cpu``), with the
network's weights rounded to float16 (half the bytes; loading casts them back to float32) and the
normalisers' ranges kept in float32: an action range rounded to float16 would move every action
by up to a millimetre. It records ``exported_from``, the SHA-256 of the policy it was made from.
A file over ``--max-mib`` (default 20) is refused, naming its size; the destination is written
atomically, so a refused or interrupted export leaves the previous file as it was.
``--if-changed`` keeps a destination exported from the same source untouched, so the records
made with it (which carry its SHA-256) stay reproducible.
"""

from __future__ import annotations

import argparse
import io
from pathlib import Path

import torch

from mani_skill_softvt.fileio import file_sha256
from mani_skill_softvt.fileio import atomic_write
from .agent import read_policy_file
from .model import load_checkpoint

MAX_MIB = 20.0
KEEP_FLOAT32 = ("normalize.",)  # state-dict prefixes kept in float32 (the normalisers' ranges)


def half_state(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The model state with floating-point weights in float16, but the normalisers'."""
    return {k: v.half() if v.is_floating_point() and not k.startswith(KEEP_FLOAT32) else v for k, v in state.items()}


def exported(source: Path, source_sha256: str) -> dict:
    """The exported policy file's content for the ``policy.pt`` (or snapshot) ``source``, whose
    file hashes to ``source_sha256``."""
    _, ckpt = read_policy_file(source)
    return {**ckpt, "model": half_state(ckpt["model"]), "weights_dtype": "float16", "exported_from": source_sha256}


def export(source: Path, dest: Path, max_mib: float = MAX_MIB, if_changed: bool = False) -> bool:
    """Write the float16 export of ``source`` to ``dest``; False if ``if_changed`` and ``dest`` was
    already exported from the same file (nothing written)."""
    source, dest = Path(source), Path(dest)
    if not dest.name.endswith(".pt") or dest.name == "policy.pt":
        raise ValueError(f"{dest}: name the export <variant>-<recipe>.pt (its records are named after the file)")
    sha = file_sha256(source) if source.is_file() else None  # a missing file: read_policy_file says so
    if if_changed and dest.exists() and load_checkpoint(dest).get("exported_from") == sha:
        return False
    buffer = io.BytesIO()
    torch.save(exported(source, sha), buffer)
    size = buffer.tell() / 2 ** 20
    if size > max_mib:
        raise ValueError(f"{source}: exported in float16 it takes {size:.1f} MiB, over the {max_mib:g} MiB a committed "
                         f"policy may take; {dest} is left as it was. Train a narrower network (encoder_widths, unet_dims)")
    atomic_write(dest, lambda tmp: tmp.write_bytes(buffer.getvalue()))
    return True


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(prog="python -m softvt_campaign.baselines.export", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("source", type=Path, help="a policy.pt (or snapshot) written by training")
    ap.add_argument("dest", type=Path, help="the exported file, e.g. campaign-data/policies/vo-c-cpu.pt")
    ap.add_argument("--max-mib", type=float, default=MAX_MIB)
    ap.add_argument("--if-changed", action="store_true", help="leave a destination exported from the same source as it is")
    args = ap.parse_args(argv)
    try:
        written = export(args.source, args.dest, args.max_mib, args.if_changed)
    except (FileNotFoundError, ValueError) as e:
        ap.error(str(e))
    size = args.dest.stat().st_size / 2 ** 20
    print(f"{args.dest}: {'written' if written else 'unchanged (exported from the same policy)'}, {size:.1f} MiB")
    return args.dest


if __name__ == "__main__":
    main()
