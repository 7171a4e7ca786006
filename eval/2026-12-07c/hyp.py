# hyp.py ROOM.json OUT.npz : screen every pair of a room (current build), save hypotheses' rotation errors vs truth
import json, sys, time, numpy as np, mtpcr
room = json.load(open(sys.argv[1]))
clouds = []
for path in room['scans']:
    s = mtpcr.read_scans(path)[0]
    clouds.append(np.asarray(s['points'], dtype=np.float64))
poses = [np.array(p) for p in room['poses']]
t0 = time.time()
scr = mtpcr.screen_pairs(*clouds, seed=0, viewpoints='origin')
print('screened', len(scr['pairs']), 'pairs in', round(time.time() - t0, 1), 's', file=sys.stderr)
rows = []
for p in scr['pairs']:
    s, t = p['source'], p['target']
    truth = np.linalg.inv(poses[t]) @ poses[s]
    for h, (T, ov, sup) in enumerate(zip(p['poses'], p['overlaps'], p['supports'])):
        R = np.asarray(T)[:3, :3] @ truth[:3, :3].T
        deg = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
        rows.append((s, t, h, deg, ov, sup, *np.asarray(T).reshape(-1)))
np.save(sys.argv[2], np.array(rows))
