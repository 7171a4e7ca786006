"""For every chosen pair / bridge look across the last round's groups: the camera distance its
join implies between capture-order neighbours (|i-j|<=K) of the two groups (groups at truth)."""
import json,re,sys,numpy as np
def matrix(t): return np.array([float(x) for x in t.split(",")]).reshape(4,4,order="F")
def error(t,g):
    r=t[:3,:3]@g[:3,:3].T; return np.degrees(np.arccos(np.clip((np.trace(r)-1)/2,-1,1))), np.linalg.norm(t[:3,3]-g[:3,3])
room,errf=sys.argv[1],sys.argv[2]; K=int(sys.argv[3]) if len(sys.argv)>3 else 2
P=[np.array(p) for p in json.load(open(room))["poses"]]; err=open(errf).read()
motion={int(m.group(1)):matrix(m.group(2)) for m in re.finditer(r"DBG motion (\d+) \[([^\]]*)\]",err)}
rounds=re.findall(r"DBG round \d+ placed \d+ groups (\[\[.*\]\])",err)
groups=json.loads(rounds[0]); gid={v:i for i,g in enumerate(groups) for v in g}
cam=lambda M,j:(M@P[j])[:3,3]
for m in re.finditer(r"DBG (chosen|look first|look second) (\d+) (\d+) .*?T \[([^\]]*)\]",err):
    kind,s,t=m.group(1),int(m.group(2)),int(m.group(3))
    if s not in gid or t not in gid or gid[s]==gid[t]: continue
    g=np.linalg.inv(motion[t])@matrix(m.group(4))@motion[s]
    a,d=error(g,np.linalg.inv(P[t])@P[s])
    A,B=groups[gid[s]],groups[gid[t]]
    M=P[s]@np.linalg.inv(g)@np.linalg.inv(P[t])   # moves B (t's group) in the world
    worst=[]
    for i in A:
        for j in B:
            if abs(i-j)<=K:
                true=np.linalg.norm(P[i][:3,3]-P[j][:3,3]); est=np.linalg.norm(P[i][:3,3]-cam(M,j))
                worst.append((abs(i-j),i,j,round(true,2),round(est,2)))
    print(kind,s,t,"RIGHT" if a<15 and d<.3 else "wrong",f"{a:.0f}deg {d:.2f}m", "nbrs:",worst)
