"""Both looks of every bridge a room registered (switches.patch, MTPCR_DEBUG_ROOM=1: `DBG look`),
whether the screened verdict trusts each, scored against the truth.

    python3 looks.py ROOM.json RUN.err
"""
import json,re,sys,numpy as np
def matrix(t): return np.array([float(x) for x in t.split(",")]).reshape(4,4,order="F")
def error(t,g):
    r=t[:3,:3]@g[:3,:3].T; return np.degrees(np.arccos(np.clip((np.trace(r)-1)/2,-1,1))), np.linalg.norm(t[:3,3]-g[:3,3])
room,errf=sys.argv[1],sys.argv[2]
poses=[np.array(p) for p in json.load(open(room))["poses"]]; err=open(errf).read()
motion={int(m.group(1)):matrix(m.group(2)) for m in re.finditer(r"DBG motion (\d+) \[([^\]]*)\]",err)}
for m in re.finditer(r"DBG look (\w+) (\d+) (\d+) odds ([-\d.]+) screened-doubt (None|Some\(.*?\)) sup (\d+) T \[([^\]]*)\]",err):
    s,t=int(m.group(2)),int(m.group(3))
    g=np.linalg.inv(motion[t])@matrix(m.group(7))@motion[s]
    a,d=error(g,np.linalg.inv(poses[t])@poses[s])
    print(m.group(1),s,t,"odds",m.group(4),"trusted" if m.group(5)=="None" else "doubted","sup",m.group(6),"RIGHT" if a<15 and d<.3 else "wrong",f"{a:.1f} {d:.2f}")
