"""Camera-anchored search for a neighbour pair: source camera put at the target camera, many
rotations, ICP each; is the truth found, and does fitness/free space rank it first?"""
import sys, numpy as np, open3d as o3d
from scipy.spatial.transform import Rotation
D='/work/shared/data/3dmatch/'
def load(scene,k):
    p=o3d.io.read_point_cloud(f'{D}{scene}/cloud_bin_{k}.ply')
    T=np.loadtxt(f'{D}{scene}/cloud_bin_{k}.info.txt',skiprows=1)
    return p,T
def angle(R): return np.degrees(np.arccos(np.clip((np.trace(R)-1)/2,-1,1)))
def panorama(pts, bins=360):
    r=np.linalg.norm(pts,axis=1); d=pts/r[:,None]
    th=np.arccos(np.clip(d[:,2],-1,1)); ph=np.arctan2(d[:,1],d[:,0])
    i=np.minimum((th/np.pi*bins/2).astype(int),bins//2-1); j=np.minimum(((ph+np.pi)/(2*np.pi)*bins).astype(int),bins-1)
    depth=np.full((bins//2,bins),np.inf); np.minimum.at(depth,(i,j),r); return depth
def freespace(depth, pts, margin=0.1, bins=360):
    r=np.linalg.norm(pts,axis=1); d=pts/r[:,None]
    th=np.arccos(np.clip(d[:,2],-1,1)); ph=np.arctan2(d[:,1],d[:,0])
    i=np.minimum((th/np.pi*bins/2).astype(int),bins//2-1); j=np.minimum(((ph+np.pi)/(2*np.pi)*bins).astype(int),bins-1)
    dd=depth[i,j]; return float(np.mean(np.isfinite(dd) & (r < dd-margin)))
scene, s, t = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
n=int(sys.argv[4]) if len(sys.argv)>4 else 500
ps,Ps=load(scene,s); pt,Pt=load(scene,t)
truth=np.linalg.inv(Pt)@Ps
print('truth: camera distance %.2f m, rotation %.1f deg, overlap-ish'%(np.linalg.norm(truth[:3,3]), angle(truth[:3,:3])))
vs=ps.voxel_down_sample(0.05); vt=pt.voxel_down_sample(0.05)
for c in (vs,vt): c.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.15,max_nn=30))
depth_t=panorama(np.asarray(vt.points)); depth_s=panorama(np.asarray(vs.points))
rots=Rotation.random(n, random_state=1).as_matrix(); rng=np.random.default_rng(2); offs=rng.normal(size=(n,3)); offs*=(rng.uniform(0,float(sys.argv[5]) if len(sys.argv)>5 else 0,n)/np.linalg.norm(offs,axis=1))[:,None]
res=[]
for R,o in zip(rots,offs):
    T=np.eye(4); T[:3,:3]=R; T[:3,3]=o
    for dist in (0.3,0.15,0.07):
        T=o3d.pipelines.registration.registration_icp(vs,vt,dist,T,o3d.pipelines.registration.TransformationEstimationPointToPlane(),o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=15)).transformation
    ev=o3d.pipelines.registration.evaluate_registration(vs,vt,0.05,T)
    src=np.asarray(vs.points)@T[:3,:3].T+T[:3,3]
    Ti=np.linalg.inv(T); tg=np.asarray(vt.points)@Ti[:3,:3].T+Ti[:3,3]
    fs=max(freespace(depth_t,src),freespace(depth_s,tg))
    D_=np.linalg.inv(truth)@T
    res.append((ev.fitness, fs, angle(D_[:3,:3]), np.linalg.norm(D_[:3,3]), np.linalg.norm(T[:3,3])))
res=np.array(res)
ok=(res[:,2]<15)&(res[:,3]<0.3)
print('right after ICP: %d of %d starts'%(ok.sum(),n))
order=np.argsort(-res[:,0])
print('top by fitness (fitness, freespace, rot err, trans err, cam dist):')
for k in order[:8]: print('  %.3f %.3f %6.1f %5.2f %5.2f %s'%(*res[k], 'RIGHT' if ok[k] else ''))
clear=res[:,1]<0.05
o2=[k for k in order if clear[k]]
print('top by fitness among clear of free space (<5%%): %d clear'%clear.sum())
for k in o2[:8]: print('  %.3f %.3f %6.1f %5.2f %5.2f %s'%(*res[k], 'RIGHT' if ok[k] else ''))
if ok.any(): print('right ones:', [('%.3f %.3f'%(res[k,0],res[k,1])) for k in np.where(ok)[0][:8]])
sel=[k for k in order if res[k,1]<0.01 and res[k,4]<1.2]
print('top by fitness with free space <1%% and cameras within 1.2 m: %d'%len(sel))
for k in sel[:5]: print('  %.3f %.3f %6.1f %5.2f %5.2f %s'%(*res[k], 'RIGHT' if ok[k] else ''))
