"""Every pair a room's screening chose (switches.patch, MTPCR_DEBUG_ROOM=1: `DBG chosen`), scored
against the truth after undoing the eval's motions; SELECT is a Python expression in s, t.

    python3 chosen.py ROOM.json RUN.err ["(s>=36)!=(t>=36)"]
"""
import json,re,sys,numpy as np
def matrix(t): return np.array([float(x) for x in t.split(",")]).reshape(4,4,order="F")
def error(t,g):
    r=t[:3,:3]@g[:3,:3].T; return np.degrees(np.arccos(np.clip((np.trace(r)-1)/2,-1,1))), np.linalg.norm(t[:3,3]-g[:3,3])
room,errf=sys.argv[1],sys.argv[2]; sel=eval("lambda s,t: "+sys.argv[3]) if len(sys.argv)>3 else (lambda s,t: True)
poses=[np.array(p) for p in json.load(open(room))["poses"]]; err=open(errf).read()
motion={int(m.group(1)):matrix(m.group(2)) for m in re.finditer(r"DBG motion (\d+) \[([^\]]*)\]",err)}
for m in re.finditer(r"DBG chosen (\d+) (\d+) h(\d+) sup (\d+) ov ([\d.]+) rej (\w+) T \[([^\]]*)\]",err):
    s,t=int(m.group(1)),int(m.group(2))
    if not sel(s,t): continue
    g=np.linalg.inv(motion[t])@matrix(m.group(7))@motion[s]
    a,d=error(g,np.linalg.inv(poses[t])@poses[s])
    print(s,t,"h"+m.group(3),"sup",m.group(4),"ov",m.group(5),"rej",m.group(6),"RIGHT" if a<15 and d<.3 else "wrong",f"{a:.1f} {d:.2f}")
