# For thresholds T: pairs whose first look has log-odds < T skip the second look, the rest as
# today. Run in a folder holding, for 3DLoMatch (-l) and 3DMatch (-m), the records of today's
# build with the LOOK lines of switches.patch (look-l.jsonl, look-l.err: first and second look's
# log-odds) and the records with no second look (one-l.jsonl: MTPCR_SKIP_BELOW=1e9); see README.
import json, sys, math
def recs(f): return {json.loads(l)['benchmark'] + ' ' + json.loads(l)['pair']: json.loads(l) for l in open(f)}
for bench, base, err, one in [('3DLoMatch','look-l.jsonl','look-l.err','one-l.jsonl'), ('3DMatch','look-m.jsonl','look-m.err','one-m.jsonl')]:
    try:
        B = recs(base); O = recs(one)
    except FileNotFoundError:
        continue
    L = {}
    for line in open(err):
        if line.startswith('LOOK '):
            _, key, a, b, k = line.split()
            L[bench + ' ' + key] = (float(a), float(b), k == 'true')
    keys = [k for k in B if k in O and k in L]
    print(bench, len(keys), 'pairs')
    def tally(pick):
        n = len(keys); reg = conf_fail = fail = dbt = 0; secs = []
        for k in keys:
            r = pick(k)
            secs.append(r['seconds'])
            if r['registered']:
                reg += 1; dbt += (not r['confident'])
            else:
                fail += 1; conf_fail += r['confident']
        secs.sort()
        return f"RR {100*reg/n:.1f} reg {reg} doubted {dbt} fail {fail} conf-fail {conf_fail} median s {secs[n//2]:.3f} total {sum(secs):.0f}"
    print('  base         ', tally(lambda k: B[k]))
    print('  never second ', tally(lambda k: O[k]))
    took = sum(1 for k in keys if not math.isnan(L[k][1]))
    print('  second looks taken', took)
    for T in [-12, -10, -8, -6, -5, -4, -3, -2, -1, 0]:
        print(f'  skip below {T:4}', tally(lambda k: O[k] if L[k][0] < T else B[k]))
