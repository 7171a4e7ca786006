"""Residuals of a room's measured pairs at the refined poses (DBG meas, MTPCR_DEBUG_MEAS=1),
each pair's relative pose scored against the truth: right (<5 deg, <15 cm), off (else, up to
15 deg / 30 cm), wrong (beyond). RUN.err files as run15.sh names them (s<seed>-<room>.err).

    ROOMS=/tmp/rooms python3 meas.py OUT/*.err
"""
import json,re,sys,glob,os,numpy as np
def matrix(t): return np.array([float(x) for x in t.split(",")]).reshape(4,4,order="F")
def error(t,g):
    r=t[:3,:3]@g[:3,:3].T; return np.degrees(np.arccos(np.clip((np.trace(r)-1)/2,-1,1))), np.linalg.norm(t[:3,3]-g[:3,3])
rooms={r.split('/')[-1][:12]:r for r in glob.glob(os.path.join(os.environ.get('ROOMS','/tmp/rooms'),'*.json'))}
rows=[]
for errf in sys.argv[1:]:
    key=errf.split('/')[-1][3:15]; P=[np.array(p) for p in json.load(open(rooms[key]))["poses"]]
    err=open(errf).read()
    motion={int(m.group(1)):matrix(m.group(2)) for m in re.finditer(r"DBG motion (\d+) \[([^\]]*)\]",err)}
    fails={(int(m.group(1)),int(m.group(2))) for m in re.finditer(r"DBG fail (\d+) (\d+) ",err)}
    for m in re.finditer(r"DBG meas (\d+) (\d+) (\d+) bridge (\w+) res ([\d.]+) self ([\d.e-]+) ov ([\d.]+) T \[([^\]]*)\]",err):
        rnd,s,t=int(m.group(1)),int(m.group(2)),int(m.group(3))
        g=np.linalg.inv(motion[t])@matrix(m.group(8))@motion[s]
        a,d=error(g,np.linalg.inv(P[t])@P[s])
        cls="right" if a<5 and d<.15 else ("wrong" if a>15 or d>.3 else "off")
        rows.append((key,errf.split('/')[-1][:2],rnd,s,t,m.group(4),float(m.group(5)),float(m.group(6)),float(m.group(7)),cls,a,d))
for cls in ("right","off","wrong"):
    r=np.array([x[6] for x in rows if x[9]==cls])
    if len(r): print(cls,len(r),"res pct 50/90/99/max",np.percentile(r,[50,90,99]).round(3),r.max().round(3),"above 0.25:",(r>0.25).sum(),"above 0.30:",(r>0.3).sum(),"above 0.35:",(r>0.35).sum())
print("pairs above 0.25:")
for x in sorted(rows,key=lambda x:-x[6]):
    if x[6]>0.25: print(" ",x[0],x[1],"round",x[2],x[3],x[4],"bridge",x[5],"res %.3f self %.3f ov %.2f"%(x[6],x[7],x[8]),x[9],"%.1f deg %.2f m"%(x[10],x[11]))
