"""The pairs a room's last round fitted its poses to (switches.patch, MTPCR_DEBUG_ROOM=1 prints them
as `DBG refined`), each against the data-fitted poses and the truth; those off by more than LIMIT
degrees (default 3) or 10 cm are printed, with the pair's screened pose beside it.

    TRUTH_CACHE=DIR python3 refined.py ROOM.json RUN.err [LIMIT]   # DIR as truth_by_icp.py left it
"""
import json,os,re,sys,numpy as np
def matrix(t): return np.array([float(x) for x in t.split(",")]).reshape(4,4,order="F")
def error(t,g):
    r=t[:3,:3]@g[:3,:3].T; return np.degrees(np.arccos(np.clip((np.trace(r)-1)/2,-1,1))), np.linalg.norm(t[:3,3]-g[:3,3])
room,errf=sys.argv[1],sys.argv[2]; lim=float(sys.argv[3]) if len(sys.argv)>3 else 3
prob=json.load(open(room)); fitted=list(np.load(os.path.join(os.environ.get("TRUTH_CACHE", "/tmp/truth-cache"), prob["name"]+".fitted.npy")))
truth=[np.array(p) for p in prob["poses"]]
err=open(errf).read()
motion={int(m.group(1)):matrix(m.group(2)) for m in re.finditer(r"DBG motion (\d+) \[([^\]]*)\]",err)}
last=err[err.rfind("DBG round"):]
chosen={}
for m in re.finditer(r"DBG chosen (\d+) (\d+) h(\d+) sup (\d+) ov ([\d.]+) rej (\w+) T \[([^\]]*)\]",err):
    chosen[(int(m.group(1)),int(m.group(2)))]=(int(m.group(4)),np.linalg.inv(motion[int(m.group(2))])@matrix(m.group(7))@motion[int(m.group(1))])
n=0
for m in re.finditer(r"DBG refined (\w+) (\d+) (\d+) w ([\d.]+) T \[([^\]]*)\]",last):
    s,t=int(m.group(2)),int(m.group(3)); n+=1
    g=np.linalg.inv(motion[t])@matrix(m.group(5))@motion[s]
    a,d=error(g,np.linalg.inv(fitted[t])@fitted[s]); at,dt=error(g,np.linalg.inv(truth[t])@truth[s])
    c=chosen.get((s,t)); cs=""
    if c: ca,cd=error(c[1],np.linalg.inv(fitted[t])@fitted[s]); cs=f"screened {ca:.1f} {cd:.2f}"
    if a>lim or d>0.1: print(m.group(1),s,t,"w",m.group(4),f"vs fitted {a:.1f} deg {d:.2f} m; vs truth {at:.1f} {dt:.2f}",cs)
print(n,"refined links")
