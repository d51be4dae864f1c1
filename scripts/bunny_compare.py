#!/usr/bin/env python3
"""Raw Stanford bunny scans -> surface: scanflow's mesh against Open3D's pipeline, both measured
against Stanford's zippered reconstruction (bun_zipper.ply) with the same function.

usage: bunny_compare.py CONF REFERENCE OURS.ply DEPTH OURS_SECONDS OURS_KIB

Open3D runs on the same aligned points (p' = R(q)^T p + t, the conjugate rotation of each
`bmesh` line, as scanflow applies it): estimate_normals (KNN 20),
orient_normals_consistent_tangent_plane(20), create_from_point_cloud_poisson(depth).

Distances (relative to the reference's bounding-box diagonal), from 200K uniform samples:
- reference -> output: every reference sample, to the output mesh;
- output -> reference, only where the reference exists: output samples whose closest reference
  point lies on a triangle that touches no boundary edge of the reference (bun_zipper has holes
  in its base; a closed output bridges them, and those bridges have no reference to compare to).
"""
import os
import resource
import sys
import time

import numpy as np
import open3d as o3d
import plyfile


def quat_matrix(x, y, z, w):
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def load_scans(conf):
    base = os.path.dirname(conf)
    pts = []
    for line in open(conf):
        t = line.split()
        if not t or t[0] != "bmesh":
            continue
        tr = np.array([float(v) for v in t[2:5]])
        r = quat_matrix(*[float(v) for v in t[5:9]])
        d = plyfile.PlyData.read(os.path.join(base, t[1]))
        p = np.stack([d["vertex"][c] for c in "xyz"], 1).astype(float)
        pts.append(p @ r + tr)  # R^T p + t for row vectors
    return np.concatenate(pts)


def mesh_of(path):
    d = plyfile.PlyData.read(path)
    v = np.stack([d["vertex"][c] for c in "xyz"], 1).astype(float)
    f = np.stack(d["face"]["vertex_indices"]).astype(np.int32)
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(f))
    return m


def scene(m):
    s = o3d.t.geometry.RaycastingScene()
    s.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(m))
    return s


def sample(m, n, seed):
    """n points uniformly by area on mesh m (seeded)."""
    v = np.asarray(m.vertices)
    f = np.asarray(m.triangles)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    rng = np.random.default_rng(seed)
    t = rng.choice(len(f), n, p=area / area.sum())
    u, w = rng.random(n), rng.random(n)
    flip = u + w > 1
    u[flip], w[flip] = 1 - u[flip], 1 - w[flip]
    return (a[t] + u[:, None] * (b[t] - a[t]) + w[:, None] * (c[t] - a[t])).astype(np.float32)


def stats(d, diag):
    d = np.asarray(d) / diag
    return dict(mean=d.mean(), rms=np.sqrt((d * d).mean()), p95=np.percentile(d, 95), max=d.max())


def measure(mesh, ref, ref_scene, ref_bad_tri, diag, n=200_000):
    out_scene = scene(mesh)
    rs = sample(ref, n, 1)
    to_out = out_scene.compute_distance(o3d.core.Tensor(rs)).numpy()
    os_ = sample(mesh, n, 2)
    cp = ref_scene.compute_closest_points(o3d.core.Tensor(os_))
    prim = cp["primitive_ids"].numpy()
    dist = np.linalg.norm(cp["points"].numpy() - os_, axis=1)
    keep = ~ref_bad_tri[prim]
    e = np.asarray(mesh.triangles)
    edges = np.sort(np.concatenate([e[:, [0, 1]], e[:, [1, 2]], e[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    comps = len(set(np.asarray(mesh.cluster_connected_triangles()[0]).tolist()))
    return dict(
        ref_to_out=stats(to_out, diag),
        out_to_ref=stats(dist[keep], diag),
        kept=keep.mean(),
        watertight=bool((counts == 2).all()),
        components=comps,
        vertices=len(mesh.vertices),
        triangles=len(mesh.triangles),
    )


def main():
    conf, reference, ours, depth, our_s, our_kib = sys.argv[1:7]
    depth = int(depth)
    ref = mesh_of(reference)
    diag = np.linalg.norm(ref.get_max_bound() - ref.get_min_bound())
    tri = np.asarray(ref.triangles)
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    uniq, inv, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    boundary_edge = counts[inv.ravel()] == 1
    bad = np.zeros(len(tri), bool)
    for k in range(3):
        bad |= boundary_edge[k * len(tri):(k + 1) * len(tri)]
    ref_scene = scene(ref)

    pts = load_scans(conf)
    t0 = time.time()
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(20))
    pc.orient_normals_consistent_tangent_plane(20)
    peer, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pc, depth=depth)
    peer_s = time.time() - t0
    peer_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    rows = [("scanflow", mesh_of(ours), float(our_s), float(our_kib)),
            ("open3d", peer, peer_s, float(peer_kib))]
    res = {name: measure(m, ref, ref_scene, bad, diag) for name, m, _, _ in rows}
    print(f"{len(pts)} points from the 10 scans, depth {depth}; reference diagonal {diag:.6f}")
    print(f"{'':10} {'seconds':>8} {'peak MiB':>9} {'verts':>8} {'comps':>5} {'closed':>6}  "
          f"{'ref->out mean':>13} {'p95':>9} {'max':>9}  {'out->ref mean':>13} {'p95':>9} {'max':>9}")
    for name, _, s, kib in rows:
        r = res[name]
        a, b = r["ref_to_out"], r["out_to_ref"]
        print(f"{name:10} {s:8.2f} {kib / 1024:9.0f} {r['vertices']:8d} {r['components']:5d} "
              f"{str(r['watertight']):>6}  {a['mean']:13.3e} {a['p95']:9.3e} {a['max']:9.3e}  "
              f"{b['mean']:13.3e} {b['p95']:9.3e} {b['max']:9.3e}")
    o, p = res["scanflow"], res["open3d"]
    r1 = o["ref_to_out"]["mean"] / p["ref_to_out"]["mean"]
    r2 = o["out_to_ref"]["mean"] / p["out_to_ref"]["mean"]
    print(f"ratio scanflow/open3d: mean ref->out {r1:.2f}, mean out->ref {r2:.2f}, "
          f"time {rows[0][2] / rows[1][2]:.2f}")
    print("out->ref kept (where the reference exists): "
          f"scanflow {o['kept']:.3f}, open3d {p['kept']:.3f}")
    met = r1 <= 1.0 and r2 <= 1.0
    print("target (no worse than Open3D's distance):", "met" if met else "not met")


if __name__ == "__main__":
    main()
