# merge_groups.py problem.json "A indices" "B indices" out_prefix seed: write A.ply (world frame), B.ply (world frame moved by a seeded motion), truth.txt (B->A)
import json, sys, numpy as np, open3d as o3d
d = json.load(open(sys.argv[1]))
A = eval(sys.argv[2]); B = eval(sys.argv[3]); out = sys.argv[4]; seed = int(sys.argv[5])
def merged(idx):
    pc = o3d.geometry.PointCloud()
    for i in idx:
        c = o3d.io.read_point_cloud(d['scans'][i]); c.transform(np.array(d['poses'][i])); pc += c
    return pc.voxel_down_sample(0.025)
a, b = merged(A), merged(B)
rng = np.random.default_rng(seed)
q = rng.normal(size=4); q /= np.linalg.norm(q)
w,x,y,z=q
R=np.array([[1-2*(y*y+z*z),2*(x*y-z*w),2*(x*z+y*w)],[2*(x*y+z*w),1-2*(x*x+z*z),2*(y*z-x*w)],[2*(x*z-y*w),2*(y*z+x*w),1-2*(x*x+y*y)]])
M = np.eye(4); M[:3,:3] = R; M[:3,3] = rng.uniform(-2,2,3)
b.transform(M)
o3d.io.write_point_cloud(out+'A.ply', a); o3d.io.write_point_cloud(out+'B.ply', b)
np.savetxt(out+'truth.txt', np.linalg.inv(M))  # B(moved) -> A
print(len(a.points), len(b.points))
