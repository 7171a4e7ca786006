"""Seconds per stage of pairs registered alone, summed (switches.patch, MTPCR_T=1 prints `T prep
...` and `T reg ...` marks; each stage is the time since the mark before it).

    MTPCR_T=1 mtpcr eval $B/3DLoMatch --pairs 40 --seed 1 --threads 2 2> t2.err; python3 stages.py t2.err
"""
import sys,collections
for f in sys.argv[1:]:
    tot=collections.OrderedDict(); prev={}
    for l in open(f):
        if not l.startswith("T "): continue
        _,kind,name,v=l.split(); v=float(v)
        if kind=="prep" and name=="sample": prev["prep"]=0.0
        if kind=="reg" and name=="hyp": prev["reg"]=0.0
        p=prev.get(kind,0.0); tot[kind+" "+name]=tot.get(kind+" "+name,0)+v-p; prev[kind]=v
    print(f, " ".join(f"{k}={v:.2f}" for k,v in tot.items()), "sum", round(sum(tot.values()),2))
