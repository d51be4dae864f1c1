#!/usr/bin/env python3
"""Open3D's reconstruction pipeline on the raw Stanford bunny scans: the peer for bench_bunny.sh.

usage: bunny_peer.py CONF DEPTH OUT.ply [--orient tangent|camera] [--neighbours 20]

Reads every `bmesh FILE tx ty tz qx qy qz qw` scan of a Scanalyze .conf (FILE relative to the
conf's directory), poses it exactly as scanflow does, p' = R(q)^T p + t (the conjugate of the
quaternion's rotation: that is what aligns the Stanford scans; bunny_compare.py checks it against
bun_zipper.ply), and runs Open3D on the merged points:

  estimate_normals(KDTreeSearchParamKNN(k))
  orient_normals_consistent_tangent_plane(k)          --orient tangent (default; issue 5's peer)
  or: flip each normal to face its scan's scanner     --orient camera  (a second, stronger peer:
      direction, R(q)^T (0,0,1), the scan's local +z   the same orientation rule scanflow uses
      carried into the common frame                    for .conf scans)
  create_from_point_cloud_poisson(depth=DEPTH)        (Open3D defaults: scale 1.1, width 0,
                                                       linear_fit False, point_weight 2 (it is
                                                       screened Poisson), samples_per_node 1.5;
                                                       n_threads = OMP_NUM_THREADS; no density
                                                       trimming, so the mesh is closed like
                                                       scanflow's)

Writes OUT.ply (binary) and prints one JSON line: points, stage seconds, Open3D version, threads.
Threads: Open3D uses OpenMP; set OMP_NUM_THREADS to pin it (bench_bunny.sh does).
"""
import argparse
import json
import os
import time

import numpy as np


def quat_matrix(x, y, z, w):
    """Rotation matrix of the unit quaternion (x, y, z, w), normalised first."""
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def read_ply_xyz(path):
    """x y z of a PLY's vertex element as float64 (n, 3).

    Fast path for the Stanford range scans (ascii, vertex element first, then a big range_grid
    element that is not needed): numpy reads just the vertex rows. Anything else goes through
    plyfile."""
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: no end_header")
            line = line.decode("ascii", "replace").strip()
            header.append(line)
            if line == "end_header":
                break
        elements = [l.split() for l in header if l.startswith("element ")]
        props = []
        in_vertex = False
        for l in header:
            t = l.split()
            if t and t[0] == "element":
                in_vertex = t[1] == "vertex"
            elif t and t[0] == "property" and in_vertex:
                props.append(t[-1])
        if ("format ascii 1.0" in header and elements and elements[0][1] == "vertex"
                and all(c in props for c in "xyz")):
            n = int(elements[0][2])
            cols = [props.index(c) for c in "xyz"]
            a = np.loadtxt(f, dtype=np.float64, max_rows=n, usecols=cols, ndmin=2)
            if len(a) != n:
                raise ValueError(f"{path}: {len(a)} vertex rows, header says {n}")
            return a
    import plyfile
    v = plyfile.PlyData.read(path)["vertex"]
    return np.stack([np.asarray(v[c], dtype=np.float64) for c in "xyz"], 1)


def read_conf(conf):
    """[(path, t (3,), R (3,3))] for every bmesh line, paths relative to the conf's directory."""
    base = os.path.dirname(os.path.abspath(conf))
    scans = []
    with open(conf) as f:
        for line in f:
            t = line.split()
            if len(t) >= 9 and t[0] == "bmesh":
                tr = np.array([float(v) for v in t[2:5]])
                scans.append((os.path.join(base, t[1]), tr, quat_matrix(*[float(v) for v in t[5:9]])))
    if not scans:
        raise ValueError(f"{conf}: no bmesh lines")
    return scans


def load_scans(conf, conjugate=True):
    """Merged posed points (n, 3), per-point scan index (n,), per-scan scanner direction (s, 3).

    conjugate=True: p' = R^T p + t (scanflow's convention); False: p' = R p + t (only used by
    bunny_compare.py to show that this one does NOT align the scans)."""
    pts, idx, dirs = [], [], []
    for i, (path, tr, r) in enumerate(read_conf(conf)):
        p = read_ply_xyz(path)
        # row vectors: p @ R == (R^T p^T)^T
        pts.append(p @ r + tr if conjugate else p @ r.T + tr)
        idx.append(np.full(len(p), i, np.int32))
        dirs.append(r.T @ np.array([0.0, 0.0, 1.0]) if conjugate else r @ np.array([0.0, 0.0, 1.0]))
    return np.concatenate(pts), np.concatenate(idx), np.array(dirs)


def write_points(path, p, n):
    """Binary little-endian PLY of float32 x y z nx ny nz."""
    a = np.empty(len(p), dtype=[(c, "<f4") for c in ("x", "y", "z", "nx", "ny", "nz")])
    for i, c in enumerate("xyz"):
        a[c], a["n" + c] = p[:, i], n[:, i]
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(a)}\n"
                 + "".join(f"property float {c}\n" for c in a.dtype.names) + "end_header\n").encode())
        f.write(a.tobytes())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("conf")
    ap.add_argument("depth", type=int)
    ap.add_argument("out")
    ap.add_argument("--orient", choices=["tangent", "camera"], default="tangent")
    ap.add_argument("--neighbours", type=int, default=20)
    ap.add_argument("--save-points", metavar="PLY",
                    help="also write the posed points with Open3D's oriented normals (binary PLY, "
                         "float32 x y z nx ny nz), to feed scanflow with --normals use")
    a = ap.parse_args()

    t0 = time.perf_counter()
    import open3d as o3d
    t_import = time.perf_counter() - t0

    t0 = time.perf_counter()
    pts, scan_of, dirs = load_scans(a.conf)
    t_read = time.perf_counter() - t0

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    t0 = time.perf_counter()
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(a.neighbours))
    t_normals = time.perf_counter() - t0

    t0 = time.perf_counter()
    if a.orient == "tangent":
        pc.orient_normals_consistent_tangent_plane(a.neighbours)
    else:
        n = np.asarray(pc.normals)
        flip = np.einsum("ij,ij->i", n, dirs[scan_of]) < 0
        n[flip] *= -1
        pc.normals = o3d.utility.Vector3dVector(n)
    t_orient = time.perf_counter() - t0

    if a.save_points:
        write_points(a.save_points, pts, np.asarray(pc.normals))

    t0 = time.perf_counter()
    threads = int(os.environ.get("OMP_NUM_THREADS") or -1)
    mesh, _densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        pc, depth=a.depth, n_threads=threads)
    t_poisson = time.perf_counter() - t0

    t0 = time.perf_counter()
    tmp = a.out + ".tmp.ply"
    if not o3d.io.write_triangle_mesh(tmp, mesh, write_ascii=False, compressed=False,
                                      write_vertex_normals=False, write_vertex_colors=False):
        raise SystemExit(f"could not write {tmp}")
    os.replace(tmp, a.out)
    t_write = time.perf_counter() - t0

    print(json.dumps(dict(
        points=len(pts), scans=len(dirs), orient=a.orient, neighbours=a.neighbours, depth=a.depth,
        import_s=t_import, read_s=t_read, normals_s=t_normals, orient_s=t_orient,
        poisson_s=t_poisson, write_s=t_write,
        pipeline_s=t_normals + t_orient + t_poisson,
        vertices=len(mesh.vertices), triangles=len(mesh.triangles),
        open3d=o3d.__version__, omp_num_threads=os.environ.get("OMP_NUM_THREADS"),
        cpus=os.cpu_count())))


if __name__ == "__main__":
    main()
