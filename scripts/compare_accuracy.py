#!/usr/bin/env python3
"""Compares the accuracy of two `mtpcr eval --json` reports of the same runs, run by run.

Usage: python3 scripts/compare_accuracy.py BEFORE.json AFTER.json

For the runs (problem, seed) in both reports, prints one line: successes and confident runs
before -> after, failed runs called confident after, and over the runs that succeed in both
the mean and median error before -> after and in how many runs it went down. The error is
Err_R x1000 when every such run has three scans, else the worst pair's or scan's rotation
error in degrees. Used when a change moves the answers (`compare_transforms.py` is for
changes that must not).
"""

import json
import statistics
import sys


def runs(path):
    with open(path) as f:
        report = json.load(f)
    return {(p["name"], r["seed"]): r for p in report["problems"] for r in p["runs"]}


def three_scans(run):
    return "err_r" in run and len(run["rot_deg"]) == 3


def error(run, err_r):
    if err_r:
        return 1000 * run["err_r"]
    return max((d for d in run["rot_deg"] if d is not None), default=float("nan"))


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    before, after = runs(sys.argv[1]), runs(sys.argv[2])
    keys = sorted(set(before) & set(after))
    if not keys:
        sys.exit("the two reports share no run (problem, seed)")

    def count(report, what):
        return sum(bool(what(report[k])) for k in keys)

    success = [count(r, lambda run: run["success"]) for r in (before, after)]
    confident = [count(r, lambda run: run["verdict"]["confident"]) for r in (before, after)]
    wrong = count(after, lambda run: not run["success"] and run["verdict"]["confident"])
    both = [k for k in keys if before[k]["success"] and after[k]["success"]]
    err_r = all(three_scans(before[k]) for k in both)
    unit = "Err_R x1000" if err_r else "worst pair or scan (deg)"
    old, new = ([error(r[k], err_r) for k in both] for r in (before, after))
    lower = sum(n < o for o, n in zip(old, new))
    line = (
        f"{len(keys)} runs: successes {success[0]} -> {success[1]}, confident "
        f"{confident[0]} -> {confident[1]}, failed but confident {wrong}"
    )
    if both:
        line += (
            f"; {unit} over the {len(both)} runs both succeed: mean "
            f"{statistics.mean(old):.2f} -> {statistics.mean(new):.2f}, median "
            f"{statistics.median(old):.2f} -> {statistics.median(new):.2f}, lower in "
            f"{lower} of {len(both)}"
        )
    print(line)


if __name__ == "__main__":
    main()
