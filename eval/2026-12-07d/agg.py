"""Fifteen room runs (run15.sh) scored against the truth and the data-fitted poses, per run and in total.

    ROOMS=/tmp/rooms TRUTH_CACHE=/tmp/truth-cache python3 agg.py OUT_DIR

Calls ../2026-12-06i/truth_by_icp.py with ~/peers-venv (Open3D) for each room.
"""
import glob, os, re, subprocess, sys, collections
d = sys.argv[1]
rooms = {os.path.basename(r)[:12]: r for r in glob.glob(os.path.join(os.environ.get("ROOMS", "/tmp/rooms"), "*.json"))}
tot = collections.Counter()
for key, room in sorted(rooms.items()):
    files = sorted(glob.glob(f"{d}/s*-{key}.json"))
    if not files: continue
    out = subprocess.run([os.path.expanduser("~/peers-venv/bin/python"), os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "2026-12-06i", "truth_by_icp.py"), room] + files,
                         capture_output=True, text=True, env=dict(os.environ, TRUTH_CACHE=os.environ.get("TRUTH_CACHE", "/tmp/truth-cache"))).stdout
    for m in re.finditer(r"(\S+) seed (\d+): placed (\d+); truth: near (\d+), wrong (\d+); data-fitted: near (\d+), wrong (\d+)", out):
        f, s, pl, nt, wt, nf, wf = m.groups()
        o = open(f[:-5] + ".out").read()
        lo = re.search(r"3DLoMatch (\d+)/(\d+), 3DMatch (\d+)/(\d+)", o)
        sec = re.search(r"\s([\d.]+)\s*$", o.splitlines()[1]).group(1) if len(o.splitlines())>1 else "?"
        print(f"{key} s{s}: placed {pl} near {nt}/{nf} wrong {wt}/{wf} pairs M {lo.group(3)} Lo {lo.group(1)} {sec}s")
        for k, v in zip(["placed","near_t","near_f","wrong_t","wrong_f","M","Lo"], [pl,nt,nf,wt,wf,lo.group(3),lo.group(1)]):
            tot[k] += int(v)
        tot["sec"] += float(sec)
print(dict(tot))
