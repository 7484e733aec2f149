"""Fingerprints of the physics, the renderer, the tactile images, the policies and the evaluator.

Prints one SHA-256 per case (mani_skill_softvt/fingerprints.py and campaign/softvt_campaign/fingerprints.py say what each covers), for
checking a code move bit for bit on one machine:

    .venv/bin/python scripts/fingerprint.py --out before.json              # at the old commit
    .venv/bin/python scripts/fingerprint.py --compare before.json          # at the new one: exit 1 on a difference

Under the pinned numerics (the default; mani_skill_softvt/provenance/numerics.py) the fingerprints are the
same on any x86-64 machine; ``tests/test_numerics.py`` checks them against the committed goldens.
``SOFTVT_NUMERICS=native`` fingerprints each library's own CPU dispatch, which holds on one machine
kind only.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from mani_skill_softvt.fingerprints import CASES as LIBRARY_CASES, policy_record
from softvt_campaign.fingerprints import CASES as BASELINE_CASES
from mani_skill_softvt.provenance.numerics import machine_kind, resolved
from mani_skill_softvt.provenance.stack import software_stack

CASES = {**LIBRARY_CASES, **BASELINE_CASES}
DEFAULT_CASES = ["expert_soft", "expert_rigid", "tactile_frame", "dp_inference", "dp_training", "calibration_trial",
                 "record"]


def write_golden(path: Path, prints: dict) -> None:
    """The goldens: per case its hashes (no per-step ones), with the numerics and machine they were made on."""
    numerics = prints["numerics"]
    if not numerics["pinned"]:
        raise SystemExit(f"goldens are made under pinned numerics; these are {numerics['name']!r}, not pinned in full")
    old = json.loads(path.read_text()) if path.exists() else {"cases": {}}
    cases = {**old["cases"], **{c: {k: v for k, v in p.items() if k != "per_step"} for c, p in prints.items()
                                if c != "numerics"}}
    cpu, flags = machine_kind(software_stack())
    here = f"{cpu} ({' '.join(flags)})"
    # A case whose hashes changed has passed only here: the machines the old goldens passed on no longer vouch.
    changed = any(old["cases"].get(c) not in (None, cases[c]) for c in cases)
    passed = {here} if changed else set(old.get("passed_on", [])) | {here}
    golden = {"numerics": numerics["name"], "warp_cpu_compiler_flags": numerics["warp_cpu_compiler_flags"],
              "made_on": here, "passed_on": sorted(passed), "cases": cases}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(golden, indent=1) + "\n")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, help="write the fingerprints here (JSON)")
    p.add_argument("--compare", type=Path, help="compare with fingerprints written before; exit 1 on a difference")
    p.add_argument("--policy", default="campaign-data/policies/object_rigid/vt-c-cpu.pt",
                   help="the policy whose record is fingerprinted")
    p.add_argument("--suite", default="object_rigid", help="the suite of that record")
    p.add_argument("--cases", nargs="+", default=DEFAULT_CASES, choices=sorted(CASES))
    p.add_argument("--golden", type=Path, help="write the cases' hashes as the tests' goldens (tests/golden/"
                   "fingerprints.json), keeping the machines the goldens have passed on")
    args = p.parse_args(argv)
    runs = {**CASES, "record": lambda: policy_record(args.policy, args.suite)}
    prints = {"numerics": resolved()}
    for case in args.cases:
        prints[case] = runs[case]()
        print(f"{case:18s} {prints[case]['episode']}", {k: v for k, v in prints[case].items()
                                                          if k in ("steps", "termination", "r_max", "last_loss")},
              flush=True)
    if args.out:
        args.out.write_text(json.dumps(prints, indent=1))
    if args.golden:
        write_golden(args.golden, prints)
    if args.compare:
        before = json.loads(args.compare.read_text())
        differ = [c for c in args.cases if c in before and before[c]["episode"] != prints[c]["episode"]]
        for c in differ:
            a, b = before[c].get("per_step", []), prints[c].get("per_step", [])
            first = next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
            print(f"DIFFERS: {c} (first at step {first}; {len(a)} against {len(b)} states)")
            parts = [k for k in ("states", "rgb", "tactile") if k in before[c] and before[c][k] != prints[c].get(k)]
            if parts:
                print(f"  its {', '.join(parts)} differ")
        print("identical, bit for bit" if not differ else f"{len(differ)} case(s) differ")
        return 1 if differ else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
