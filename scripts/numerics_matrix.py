"""What moves the bits: each part of the numerics pinned alone, from this machine's native dispatch.

Runs ``scripts/fingerprint.py`` once with every library's own CPU dispatch (``native``), once per
part of :data:`mani_skill_softvt.provenance.numerics.PARTS` pinned alone (``x86-64-v3:<part>``), and once with
all of them pinned (``x86-64-v3``), each in a fresh process (the variables are read as the libraries
load), and prints which fingerprint each changes against native: on a machine whose native dispatch
is x86-64-v3 (AVX2, FMA) nothing moves; on an AVX-512 machine the parts that dispatch by ISA do.

    .venv/bin/python scripts/numerics_matrix.py                       # about 10 min on one core
    .venv/bin/python scripts/numerics_matrix.py --cases tactile_frame dp_inference --parts aten onednn
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from mani_skill_softvt.provenance.numerics import NATIVE, NUMERICS_ENV, PARTS, PINNED

ROOT = Path(__file__).resolve().parent.parent
COLUMNS = {"expert_soft": ("states", "rgb", "tactile"), "expert_rigid": ("states", "rgb", "tactile"),
           "tactile_frame": ("episode",), "dp_inference": ("episode",), "dp_training": ("episode",)}


def fingerprints(numerics: str, cases: list[str], tmp: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in {var for p in PARTS.values() for var in p}}
    env[NUMERICS_ENV] = numerics
    out = tmp / f"{numerics.replace(':', '_').replace(',', '_')}.json"
    subprocess.run([sys.executable, str(ROOT / "scripts" / "fingerprint.py"), "--cases", *cases, "--out", str(out)],
                   env=env, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return json.loads(out.read_text())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=list(COLUMNS), choices=list(COLUMNS))
    ap.add_argument("--parts", nargs="+", default=list(PARTS), choices=list(PARTS))
    args = ap.parse_args(argv)
    rows = [NATIVE] + [f"{PINNED}:{p}" for p in args.parts] + [PINNED]
    cols = [(c, k) for c in args.cases for k in COLUMNS[c]]
    with tempfile.TemporaryDirectory() as tmp:
        prints = {}
        for i, row in enumerate(rows):
            print(f"[{i + 1}/{len(rows)}] {row}", file=sys.stderr, flush=True)
            prints[row] = fingerprints(row, args.cases, Path(tmp))
    native = prints[NATIVE]
    print(f"machine: {native['numerics'].get('torch_cpu_capability')} torch, OpenBLAS {native['numerics'].get('openblas_core')}, "
          f"NumPy AVX-512 {native['numerics'].get('numpy_avx512')}, OpenCV AVX-512 {native['numerics'].get('opencv_avx512')}")
    header = ["numerics"] + [f"{c}.{k}" if k != "episode" else c for c, k in cols]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows[1:]:
        cells = ["moved" if prints[row][c][k] != native[c][k] else "-" for c, k in cols]
        print(f"| {row} | " + " | ".join(cells) + " |")
    steps = {row: prints[row]["expert_soft"]["steps"] for row in rows if "expert_soft" in prints[row]}
    if steps:
        print("expert_soft steps:", steps)
    return 0


if __name__ == "__main__":
    sys.exit(main())
