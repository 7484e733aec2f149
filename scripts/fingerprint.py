"""Fingerprints of the physics, the renderer, the tactile images, the policies and the evaluator.

Prints one SHA-256 per case (mani_skill_softvt/fingerprints.py and campaign/softvt_campaign/fingerprints.py say what each covers), for
checking a code move bit for bit on one machine:

    .venv/bin/python scripts/fingerprint.py --out before.json              # at the old commit
    .venv/bin/python scripts/fingerprint.py --compare before.json          # at the new one: exit 1 on a difference
    .venv/bin/python scripts/fingerprint.py --golden tests/golden/fingerprints.json   # on a new machine kind

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
from softvt_campaign.fingerprints import CASES as BASELINE_CASES, dp_inference_trace, first_difference
from mani_skill_softvt.provenance.numerics import machine_kind, resolved
from mani_skill_softvt.provenance.stack import software_stack

CASES = {**LIBRARY_CASES, **BASELINE_CASES}
DEFAULT_CASES = ["expert_soft", "expert_rigid", "tactile_frame", "dp_inference", "dp_training",
                 "dp_training_float32_products", "calibration_trial", "record"]


HASHES = ("episode", "states", "rgb", "tactile", "pressure", "rigid", "geometric", "losses", "weights")


def hashes_of(case: dict) -> dict:
    """A case's hashes (what a golden vouches for), without its per-step ones and its provenance."""
    return {k: v for k, v in case.items() if k in HASHES}


def read_fingerprints(path: Path) -> dict:
    """Per case, its fingerprints from a file of ``--out`` or of goldens (whose cases sit under "cases")."""
    data = json.loads(path.read_text())
    return data["cases"] if "cases" in data else {k: v for k, v in data.items() if k != "numerics"}


def write_golden(path: Path, prints: dict, remake: bool = False) -> list[str]:
    """Record this machine in each case's ``passed_on`` where its hashes are the golden ones; a case
    new to the file is made here. A case that differs is left as it is and returned, unless ``remake``
    (the code changed what it computes): then it is made here, and only here has it passed."""
    numerics = prints["numerics"]
    if not numerics["pinned"]:
        raise SystemExit(f"goldens are made under pinned numerics; these are {numerics['name']!r}, not pinned in full")
    old = json.loads(path.read_text()) if path.exists() else {"cases": {}}
    cpu, flags = machine_kind(software_stack())
    here = f"{cpu} ({' '.join(flags)})"
    cases, differ = dict(old["cases"]), []
    for c, p in prints.items():
        if c == "numerics":
            continue
        made = {k: v for k, v in p.items() if k != "per_step"}
        before = old["cases"].get(c)
        if before is not None and hashes_of(before) != hashes_of(made) and not remake:
            differ.append(c)
        elif before is not None and hashes_of(before) == hashes_of(made):
            cases[c] = {**before, "passed_on": sorted({*before.get("passed_on", []), here})}
        else:
            cases[c] = {**made, "made_on": here, "passed_on": [here]}
    golden = {"numerics": numerics["name"], "warp_cpu_compiler_flags": numerics["warp_cpu_compiler_flags"],
              "cases": cases}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(golden, indent=1) + "\n")
    tmp.replace(path)
    return differ


def trace_main(out: Path | None, compare: Path | None) -> int:
    """dp_inference call by call: written to ``out``, or compared with ``compare`` (its first difference)."""
    stack = software_stack()
    cpu, flags = machine_kind(stack)
    numerics, torch_version = resolved()["name"], stack.get("torch")
    calls = dp_inference_trace()
    if out:
        out.write_text(json.dumps({"made_on": f"{cpu} ({' '.join(flags)})", "numerics": numerics,
                                   "torch": torch_version, "calls": calls}, indent=0) + "\n")
        print(f"{len(calls)} calls written to {out}")
    if compare:
        before = json.loads(compare.read_text())
        for what, there, here in (("numerics", before.get("numerics"), numerics), ("torch", before.get("torch"), torch_version)):
            if there != here:  # then a difference says nothing of the CPU
                print(f"WARNING: {compare} was traced under {what} {there}, this run under {here}")
        i = first_difference(before["calls"], calls)
        if i is None:
            print(f"the same {len(calls)} calls, bit for bit, as on {before['made_on']}")
            return 0
        print(f"first difference at call {i} (here {len(calls)} calls, there {len(before['calls'])}; "
              f"against {before['made_on']}):")
        for j in range(max(0, i - 3), i + 3):
            a = calls[j] if j < len(calls) else "(ended)"
            b = before["calls"][j] if j < len(before["calls"]) else "(ended)"
            print(f"  {j:5d}  here {a:40s} there {b}{'   <-' if j == i else ''}")
        return 1
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, help="write the fingerprints here (JSON)")
    p.add_argument("--compare", type=Path, help="compare with fingerprints written before; exit 1 on a difference")
    p.add_argument("--policy", default="campaign-data/policies/object_rigid/vt-c-cpu.pt",
                   help="the policy whose record is fingerprinted")
    p.add_argument("--suite", default="object_rigid", help="the suite of that record")
    p.add_argument("--cases", nargs="+", default=DEFAULT_CASES, choices=sorted(CASES))
    p.add_argument("--golden", type=Path, help="check the cases against the tests' goldens (tests/golden/"
                   "fingerprints.json) and add this machine to each matching case's passed_on; exit 1 on a difference")
    p.add_argument("--remake", action="store_true", help="with --golden: make the cases that differ here (the code "
                   "changed what they compute; the other machines they passed on no longer vouch for them)")
    p.add_argument("--trace", type=Path, help="write dp_inference's call-by-call trace here (JSON) and stop")
    p.add_argument("--trace-compare", type=Path, help="compare dp_inference's trace with one written before (on "
                   "another CPU vendor, say): print the first call that differs; exit 1 on a difference")
    args = p.parse_args(argv)
    if args.trace or args.trace_compare:
        return trace_main(args.trace, args.trace_compare)
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
        kept = write_golden(args.golden, prints, remake=args.remake)
        for c in kept:
            print(f"DIFFERS from the golden: {c} (left as it was; --remake makes it here)")
        if kept:
            return 1
    if args.compare:
        before = read_fingerprints(args.compare)
        missing = [c for c in args.cases if c not in before]
        if missing:  # a comparison that compares nothing must not read as a pass
            print(f"{args.compare} has no fingerprints of {', '.join(missing)}: nothing to compare them with")
            return 1
        differ = [c for c in args.cases if hashes_of(before[c]) != hashes_of(prints[c])]
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
