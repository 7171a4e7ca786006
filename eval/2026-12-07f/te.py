import json,sys,statistics as st
runs={f:{x['pair']:x for x in map(json.loads,open(f))} for f in sys.argv[1:]}
common=set.intersection(*[set(k for k,v in r.items() if v['registered']) for r in runs.values()])
for f,r in runs.items():
    reg=[v for v in r.values() if v['registered']]
    print('%-18s reg %d TE %.4f RE %.3f | common %d TE %.4f RE %.3f | med s %.3f sum %.1f'%(f,len(reg),st.mean(v['te'] for v in reg),st.mean(v['re_deg'] for v in reg),len(common),st.mean(r[k]['te'] for k in common),st.mean(r[k]['re_deg'] for k in common),st.median(v['seconds'] for v in r.values()),sum(v['seconds'] for v in r.values())))
