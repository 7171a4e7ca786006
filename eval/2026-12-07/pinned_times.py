"""The table of pinned_times.sh: each room's seconds (two rounds) before and after, and the ratio."""
import glob
import json
import os
import sys

rows = {}
for f in sorted(glob.glob(os.path.join(sys.argv[1], "*.json"))):
    build, _order, room = os.path.basename(f)[:-5].split("-", 2)
    run = json.load(open(f))["problems"][0]["runs"][0]
    rows.setdefault(room, {}).setdefault(build, []).append(run["seconds"])
total = {"before": 0.0, "after": 0.0}
print("| room | before (s) | after (s) | ratio |\n|---|---|---|---|")
for room, d in rows.items():
    if len(d.get("before", [])) < 2 or len(d.get("after", [])) < 2:
        print(f"| {room} | incomplete | | |")
        continue
    b, a = sum(d["before"]), sum(d["after"])
    total["before"] += b
    total["after"] += a
    fmt = lambda xs: " / ".join(f"{x:.1f}" for x in xs)
    print(f"| {room} | {fmt(d['before'])} | {fmt(d['after'])} | {a / b:.3f} |")
if total["before"]:
    print(f"| all | | | {total['after'] / total['before']:.3f} |")
