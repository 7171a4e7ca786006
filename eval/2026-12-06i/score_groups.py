# score_groups.py OUT TRUTH: rotation / translation error of `mtpcr register A.ply B.ply -o OUT`'s T12
# against merge_groups.py's truth (B -> A).
import json,sys,numpy as np
r=json.load(open(sys.argv[1]+'/result.json'))
T=np.array(r['transforms']['T12']); G=np.loadtxt(sys.argv[2])  # G: B->A; T12: A->B
D=G@T
ang=np.degrees(np.arccos(np.clip((np.trace(D[:3,:3])-1)/2,-1,1)))
print('rot err', round(ang,2), 'trans', round(np.linalg.norm(D[:3,3]),3), 'confident', r['confident'])
