# Write an E57 file of six scans of a synthetic point set (test helper): each point goes to
# the scanner 50 units out along the axis it faces most, each scan stored in its own frame
# (rotated about a tilted axis) with its pose, colour and intensity.
# Usage: e57_scans.py IN.ply OUT.e57 [CRS], CRS going to the root's coordinateMetadata.
import sys, numpy as np, plyfile, pye57, pye57.e57
src, out = sys.argv[1], sys.argv[2]
crs = sys.argv[3] if len(sys.argv) > 3 else ""
v = plyfile.PlyData.read(src)['vertex']
P = np.stack([v['x'], v['y'], v['z']], 1).astype(np.float64)
def rot(axis, deg):
    a = np.radians(deg); c, s = np.cos(a), np.sin(a)
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K
def quat(axis, deg):
    a = np.radians(deg) / 2
    return np.array([np.cos(a), *(np.sin(a) * np.asarray(axis, float))])
dirs = np.array([[1,0,0],[-1,0,0],[0,1,0],[0,-1,0],[0,0,1],[0,0,-1]], float)
owner = np.argmax(P @ dirs.T, axis=1)
# pye57 writes coordinateMetadata as "" when it opens a file for writing, and an E57 node is
# set once: its string constructor gives the CRS instead while the file is opened.
string_node = pye57.e57.libe57.StringNode
pye57.e57.libe57.StringNode = lambda imf, v="": string_node(imf, v if v else crs)
e = pye57.E57(out, mode='w')
pye57.e57.libe57.StringNode = string_node
for k, d in enumerate(dirs):
    W = P[owner == k]
    t = 50.0 * d
    axis = np.array([0.3, -0.5, 0.8]); axis /= np.linalg.norm(axis)
    deg = 25.0 * (k + 1)
    R = rot(axis, deg)
    L = (W - t) @ R          # local = R^T (world - t)
    n = len(L)
    e.write_scan_raw({'cartesianX': L[:, 0], 'cartesianY': L[:, 1], 'cartesianZ': L[:, 2],
                      'intensity': np.linspace(0, 1, n),
                      'colorRed': np.full(n, 200, np.uint8), 'colorGreen': np.full(n, 100, np.uint8),
                      'colorBlue': np.full(n, 50, np.uint8)},
                     rotation=quat(axis, deg), translation=t)
e.close()
r = pye57.E57(out)
print(r.scan_count, sum(r.get_header(i).point_count for i in range(r.scan_count)))
