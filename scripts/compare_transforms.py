#!/usr/bin/env python3
"""Checks that two `mtpcr eval --json` reports hold bit-identical transforms.

Usage: python3 scripts/compare_transforms.py BEFORE.json AFTER.json

Every run (problem, seed) of BEFORE must be in AFTER with exactly the same transforms (the
poses for runs of other than three scans; JSON numbers are written in shortest round-trip
form, so equal doubles print equally). Exits 1 and
lists the differences otherwise. Used to show that a refactoring changes no result.
"""

import json
import sys


def runs(path):
    with open(path) as f:
        report = json.load(f)
    out = {}
    for problem in report["problems"]:
        for run in problem["runs"]:
            # Three-scan runs report transforms, runs of other view counts the poses.
            found = run.get("transforms", run.get("poses"))
            if found is None:
                sys.exit(f"{path}: run without transforms (written by an older mtpcr eval)")
            out[(problem["name"], run["seed"])] = found
    return out


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    before, after = runs(sys.argv[1]), runs(sys.argv[2])
    missing = sorted(set(before) - set(after))
    differ = sorted(k for k in before if k in after and before[k] != after[k])
    for k in missing:
        print(f"missing in {sys.argv[2]}: {k[0]} seed {k[1]}")
    for k in differ:
        # An unplaced scan's pose is null: compare only matrices present in both.
        worst = max(
            (
                abs(a - b)
                for ta, tb in zip(before[k], after[k])
                if ta is not None and tb is not None
                for ra, rb in zip(ta, tb)
                for a, b in zip(ra, rb)
            ),
            default=float("nan"),
        )
        print(f"differs: {k[0]} seed {k[1]} (largest entry difference {worst:.3e})")
    same = len(before) - len(missing) - len(differ)
    print(f"{same} of {len(before)} runs bit-identical")
    sys.exit(1 if missing or differ else 0)


if __name__ == "__main__":
    main()
