import sys, numpy as np, open3d as o3d
D='/work/shared/data/3dmatch/'
def load(scene,k):
    return o3d.io.read_point_cloud(f'{D}{scene}/cloud_bin_{k}.ply'), np.loadtxt(f'{D}{scene}/cloud_bin_{k}.info.txt',skiprows=1)
def angle(R): return np.degrees(np.arccos(np.clip((np.trace(R)-1)/2,-1,1)))
scene,s,t=sys.argv[1],int(sys.argv[2]),int(sys.argv[3])
ps,Ps=load(scene,s); pt,Pt=load(scene,t); truth=np.linalg.inv(Pt)@Ps
vs=ps.voxel_down_sample(0.05); vt=pt.voxel_down_sample(0.05)
for c in (vs,vt): c.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.15,max_nn=30))
ev=o3d.pipelines.registration.evaluate_registration(vs,vt,0.05,truth)
T=truth
for dist in (0.3,0.15,0.07):
    T=o3d.pipelines.registration.registration_icp(vs,vt,dist,T,o3d.pipelines.registration.TransformationEstimationPointToPlane(),o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=15)).transformation
D_=np.linalg.inv(truth)@T
print(scene[:12],s,t,'fitness at truth %.3f; ICP from truth moves %.1f deg %.2f m, fitness %.3f'%(ev.fitness, angle(D_[:3,:3]), np.linalg.norm(D_[:3,3]), o3d.pipelines.registration.evaluate_registration(vs,vt,0.05,T).fitness))
