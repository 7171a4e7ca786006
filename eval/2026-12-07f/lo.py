import json,sys,statistics as st
for f in sys.argv[1:]:
    r=[json.loads(l) for l in open(f)]
    reg=[y for y in r if y['registered']]; fail=[y for y in r if not y['registered']]
    fc=sum(y['confident'] for y in fail); rd=sum(not y['confident'] for y in reg)
    print('%-28s n %d RR %.1f RE %.3f TE %.4f fc %d/%d rd %d/%d med %.3f sum %.0f'%(f,len(r),100*len(reg)/len(r),st.mean(y['re_deg'] for y in reg),st.mean(y['te'] for y in reg),fc,len(fail),rd,len(reg),st.median(y['seconds'] for y in r),sum(y['seconds'] for y in r)))
