#!/usr/bin/env python3
"""Summarizes `mtpcr eval --json` reports: successes, the verdict against the truth, time.

    python3 scripts/summarize_eval.py REPORT.json [REPORT.json ...]

Prints, per report, one Markdown table row: runs, successes, and the four cells of the
verdict's calibration (a success the verdict calls confident, a success it doubts, a failure
it doubts, a failure it calls confident: the dangerous cell), the median and largest seconds
per run, then the runs that failed or were doubted.
"""

import json
import statistics
import sys


def summarize(path):
    report = json.load(open(path))
    runs = [(p["name"], r) for p in report["problems"] for r in p["runs"]]
    cells = {(True, True): 0, (True, False): 0, (False, False): 0, (False, True): 0}
    notes = []
    for name, r in runs:
        confident = r["verdict"]["confident"]
        cells[(r["success"], confident)] += 1
        if not (r["success"] and confident):
            worst = max((d for d in r["rot_deg"] if d is not None), default=float("nan"))
            unplaced = sum(d is None for d in r["rot_deg"])
            what = "ok" if r["success"] else "FAIL"
            trust = "confident" if confident else "not confident"
            extra = f", {unplaced} unplaced" if unplaced else ""
            reasons = "; ".join(r["verdict"]["reasons"])[:160]
            notes.append(
                f"  {name} seed {r['seed']}: {what}, {trust}, worst {worst:.1f} deg{extra}"
                f" [{reasons}]"
            )
    seconds = [r["seconds"] for _, r in runs]
    ok = sum(r["success"] for _, r in runs)
    print(
        f"| {path.rsplit('/', 1)[-1]} | {len(runs)} | {ok} | {cells[(True, True)]} "
        f"| {cells[(True, False)]} | {cells[(False, False)]} | {cells[(False, True)]} "
        f"| {statistics.median(seconds):.1f} | {max(seconds):.1f} |"
    )
    return notes


def main():
    print(
        "| report | runs | successes | ok, confident | ok, not confident "
        "| failed, not confident | failed, confident | median s | max s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    notes = {path: summarize(path) for path in sys.argv[1:]}
    for path, lines in notes.items():
        if lines:
            print(f"\n{path}:")
            print("\n".join(lines))


if __name__ == "__main__":
    main()
