# Each bridge's two looks (BRIDGE lines of the dump) scored against the truth:
# python3 bridges.py problem.json run.err...
import json, sys, numpy as np
prob=json.load(open(sys.argv[1])); P=[np.array(p) for p in prob['poses']]
def ang(d): return np.degrees(np.arccos(np.clip((np.trace(d[:3,:3])-1)/2,-1,1)))
for f in sys.argv[2:]:
    M={}
    print(f)
    for line in open(f):
        if line.startswith('MOTION'):
            a=line.split(' ',2); m=np.eye(4); m[:3]=np.array([float(x) for x in a[2].strip().strip('[]').split(',')]).reshape(3,4); M[int(a[1])]=m
        if line.startswith('BRIDGE'):
            a=line.split(' '); s,t=int(a[1]),int(a[2])
            m=np.eye(4); m[:3]=np.array([float(x) for x in line.split('[')[-1].strip().strip(']').split(',')]).reshape(3,4)
            tr=M[t]@np.linalg.inv(P[t])@P[s]@np.linalg.inv(M[s])
            d=np.linalg.inv(tr)@m
            print(' ',s,t,a[3],'six',a[4],'nine',a[5],'agree',a[6],'re',round(ang(d),1),'te',round(np.linalg.norm(m[:3,3]-tr[:3,3]),2))
