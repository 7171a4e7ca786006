import json,sys,os,glob
a,b=sys.argv[1],sys.argv[2]
def strip(x):
    if isinstance(x,dict): return {k:strip(v) for k,v in x.items() if 'second' not in k and k!='pairs_per_second'}
    if isinstance(x,list): return [strip(v) for v in x]
    return x
n=same=0; ta=tb=0
for f in sorted(glob.glob(b+'/*.json')):
    g=os.path.join(a,os.path.basename(f))
    try: y=json.load(open(f)); x=json.load(open(g))
    except Exception as e: continue
    n+=1; same+= strip(x)==strip(y)
    def secs(z):
        s=0
        if isinstance(z,dict):
            for k,v in z.items():
                if k=='seconds' and isinstance(v,(int,float)): s+=v
                else: s+=secs(v)
        elif isinstance(z,list): s+=sum(secs(v) for v in z)
        return s
    ta+=secs(x); tb+=secs(y)
print('compared',n,'identical',same,'seconds',round(ta,1),round(tb,1))
