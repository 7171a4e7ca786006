# Totals over room runs: python3 tab.py DIR (DIR holds TAG-sSEED-ROOM.json, mtpcr eval --json)
import json, glob, os, collections, sys
tot = collections.defaultdict(lambda: collections.Counter())
cells = collections.defaultdict(dict)
for f in sorted(glob.glob(sys.argv[1] + '/*.json')):
    b = os.path.basename(f)[:-5]; tag, seed, room = b.split('-', 2)
    r = json.load(open(f))['problems'][0]['runs'][0]
    placed = sum(a is not None for a in r['rot_deg'])
    near = sum(1 for a, t in zip(r['rot_deg'], r['translation']) if a is not None and a < 5 and t < 0.15)
    ps = {s['name']: (s['recovered'], s['total']) for s in r['pair_sets']}
    c = tot[tag]
    c['placed'] += placed; c['wrong'] += r['wrong']; c['bwrong'] += r['best_anchor']['wrong']; c['bnear'] += r['best_anchor']['near']; c['near'] += near
    c['m'] += ps['3DMatch'][0]; c['mt'] += ps['3DMatch'][1]; c['l'] += ps['3DLoMatch'][0]; c['lt'] += ps['3DLoMatch'][1]
    c['s'] += r['seconds']
    cells[room][(tag, seed)] = f"{placed}/{r['wrong']}/{r['best_anchor']['wrong']}"
for room, d in cells.items():
    print(room, ' | '.join(f"{k[0]} {k[1]}: {v}" for k, v in sorted(d.items())))
for tag, c in tot.items():
    print(tag, dict(c))
