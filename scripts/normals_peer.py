#!/usr/bin/env python3
"""Open3D's normal estimation on the same points as scanflow, and both against the exact normals.

usage: normals_peer.py BARE.ply TRUTH.ply [--ours LABEL REPORTED_S INGEST_S STORE ...]
                       [--plain-ingest-seconds S] [--neighbours 20] [--orient] [--repeat R]

BARE.ply: the points (x y z, no normals) both tools get. TRUTH.ply: the same points with the
exact normals of the synthetic surface (scanflow synth's output). Times, on BARE.ply's points:
  Open3D estimate_normals(KDTreeSearchParamKNN(k))                 (PCA plane fit, no orientation)
      once in the input order and once on the same points sorted along a Morton curve (synth
      writes points in random order, which makes Open3D's neighbour queries ~4x slower; scanflow
      works on its store's spatially bucketed cells); ratios use the faster of the two
  Open3D orient_normals_consistent_tangent_plane(k)  with --orient (Hoppe's MST propagation),
      on the sorted cloud
Threads: Open3D's OpenMP pool (set OMP_NUM_THREADS; bench_normals.sh sets it to THREADS).

Accuracy, for each --ours store (made by `scanflow ingest --normals estimate`): the store's
normals are read back (manifest.json + zstd cells of fixed-width records), matched to
the truth by exact position (the store keeps the input's float32 coordinates exactly), and
reported as the angle to the exact normal (unoriented: acos|n.t|, mean and p95, degrees) and the
fraction pointing inward (n.t < 0; the tools orient outward). Open3D's are reported the same way;
its estimate_normals alone leaves the sign arbitrary, and orient_normals_consistent_tangent_plane
makes it consistent but not necessarily outward, so its flipped fraction is also given as
min(f, 1 - f) (consistency up to one global flip).
"""
import argparse
import json
import os
import shutil
import subprocess
import time

import numpy as np

PLY_TYPES = {"float": "f4", "float32": "f4", "double": "f8", "float64": "f8", "uchar": "u1",
             "uint8": "u1", "char": "i1", "int8": "i1", "ushort": "u2", "uint16": "u2",
             "short": "i2", "int16": "i2", "uint": "u4", "uint32": "u4", "int": "i4", "int32": "i4"}


def read_ply_vertices(path):
    """Structured array of a binary PLY's vertex element (vertex element first, no lists)."""
    with open(path, "rb") as f:
        fmt, n, props, first = None, None, [], True
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: no end_header")
            t = line.decode("ascii", "replace").split()
            if not t:
                continue
            if t[0] == "format":
                fmt = t[1]
            elif t[0] == "element":
                if n is not None:
                    first = False
                elif t[1] == "vertex" and first:
                    n = int(t[2])
                else:
                    first = False
            elif t[0] == "property" and n is not None and first:
                if t[1] == "list":
                    raise ValueError(f"{path}: list property in vertex element")
                props.append((t[2], PLY_TYPES[t[1]]))
            elif t[0] == "end_header":
                break
        if fmt not in ("binary_little_endian", "binary_big_endian") or n is None:
            import plyfile
            return plyfile.PlyData.read(path)["vertex"].data
        end = "<" if fmt == "binary_little_endian" else ">"
        dt = np.dtype([(name, end + ty) for name, ty in props])
        a = np.fromfile(f, dtype=dt, count=n)
        if len(a) != n:
            raise ValueError(f"{path}: {len(a)} vertices, header says {n}")
        return a


def write_xyz_ply(path, v):
    """Binary little-endian float32 x y z PLY of structured array v's x y z."""
    a = np.empty(len(v), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    for c in "xyz":
        a[c] = v[c]
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(a)}\n"
                 "property float x\nproperty float y\nproperty float z\nend_header\n").encode())
        f.write(a.tobytes())


def zstd_decompress(path):
    try:
        import zstandard
        with open(path, "rb") as f:
            return zstandard.ZstdDecompressor().stream_reader(f, read_across_frames=True).read()
    except ImportError:
        if not shutil.which("zstd"):
            raise SystemExit("reading the store needs python zstandard or the zstd command")
        return subprocess.run(["zstd", "-dcq", path], check=True, capture_output=True).stdout


def read_store(store):
    """Structured array of every record of a scanflow store (fields as its manifest says)."""
    m = json.load(open(os.path.join(store, "manifest.json")))
    types = {"f64": "<f8", "f32": "<f4", "u8": "u1", "u16": "<u2", "u32": "<u4", "i32": "<i4",
             "i16": "<i2", "u64": "<u8"}
    dt = np.dtype([(f.split(":")[0], types[f.split(":")[1]]) for f in m["record_fields"]])
    if dt.itemsize != m["record_bytes"]:
        raise SystemExit(f"{store}: record fields {m['record_fields']} are {dt.itemsize} bytes, "
                         f"manifest says {m['record_bytes']}")
    parts = [np.frombuffer(zstd_decompress(os.path.join(store, "cells", c["file"])), dtype=dt)
             for c in m["cells"]]
    a = np.concatenate(parts)
    if len(a) != m["point_count"]:
        raise SystemExit(f"{store}: {len(a)} records, manifest says {m['point_count']}")
    return a, m


def match(pos_a, pos_b):
    """Permutation p with pos_b[p] == pos_a (exact float32 positions), or None."""
    ka = np.lexsort((pos_a[:, 2], pos_a[:, 1], pos_a[:, 0]))
    kb = np.lexsort((pos_b[:, 2], pos_b[:, 1], pos_b[:, 0]))
    if not np.array_equal(pos_a[ka], pos_b[kb]):
        return None
    p = np.empty(len(pos_a), np.int64)
    p[ka] = kb
    return p


def morton_order(p, bits=10):
    """Indices sorting points (n, 3) along a Morton (Z-order) curve of 2^bits cells per axis."""
    q = ((p - p.min(0)) / max(float(np.ptp(p, 0).max()), 1e-30) * ((1 << bits) - 1)).astype(np.uint64)

    def spread(x):  # 10 bits -> every third bit
        x = (x | (x << np.uint64(16))) & np.uint64(0x30000FF)
        x = (x | (x << np.uint64(8))) & np.uint64(0x300F00F)
        x = (x | (x << np.uint64(4))) & np.uint64(0x30C30C3)
        return (x | (x << np.uint64(2))) & np.uint64(0x9249249)

    code = spread(q[:, 0]) | (spread(q[:, 1]) << np.uint64(1)) | (spread(q[:, 2]) << np.uint64(2))
    return np.argsort(code, kind="stable")


def accuracy(n, t):
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    d = np.einsum("ij,ij->i", n, t)
    ang = np.degrees(np.arccos(np.clip(np.abs(d), 0, 1)))
    flipped = float((d < 0).mean())
    return dict(mean_deg=float(ang.mean()), p95_deg=float(np.percentile(ang, 95)),
                flipped=flipped, flipped_up_to_global=min(flipped, 1 - flipped))


def fmt_acc(a):
    return (f"angle to exact normal mean {a['mean_deg']:.2f} deg, p95 {a['p95_deg']:.2f} deg; "
            f"inward {100 * a['flipped']:.3f}% (up to one global flip {100 * a['flipped_up_to_global']:.3f}%)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bare")
    ap.add_argument("truth")
    ap.add_argument("--ours", nargs=4, action="append", default=[],
                    metavar=("LABEL", "REPORTED_S", "INGEST_S", "STORE"),
                    help="one scanflow mode: its label, the normal-estimation seconds it reported "
                         "('-' if none), the whole `ingest --normals estimate` seconds, its store "
                         "('-' to skip reading it back). The first one is judged against the target.")
    ap.add_argument("--plain-ingest-seconds", type=float,
                    help="`ingest --normals use` of the file with normals: the baseline subtracted "
                         "from a whole ingest when a mode reported no figure")
    ap.add_argument("--neighbours", type=int, default=20)
    ap.add_argument("--orient", action="store_true",
                    help="also time orient_normals_consistent_tangent_plane (minutes and ~2.6 KB/point)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="best of this many timings of estimate_normals on the sorted points")
    ap.add_argument("--json")
    a = ap.parse_args()

    import open3d as o3d
    truth = read_ply_vertices(a.truth)
    bare = read_ply_vertices(a.bare)
    n = len(bare)
    pos = np.stack([bare[c] for c in "xyz"], 1).astype(np.float32)
    tpos = np.stack([truth[c] for c in "xyz"], 1).astype(np.float32)
    if not np.array_equal(pos, tpos):
        raise SystemExit("the bare points are not the truth file's points in the same order")
    tn = np.stack([truth[c] for c in ("nx", "ny", "nz")], 1).astype(np.float64)
    tn /= np.linalg.norm(tn, axis=1, keepdims=True)

    k = a.neighbours
    res = dict(points=n, neighbours=k, omp_num_threads=os.environ.get("OMP_NUM_THREADS"),
               cpus=os.cpu_count(), open3d=o3d.__version__, ours=[])
    # Input order (as given to both tools; synth writes points in random order) ...
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pos.astype(np.float64)))
    t0 = time.perf_counter()
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(k))
    res["o3d_estimate_s"] = time.perf_counter() - t0
    res["o3d_estimate_acc"] = accuracy(np.asarray(pc.normals), tn)
    del pc
    # ... and Morton-sorted, as scanflow's store holds them (cache-friendly neighbour queries;
    # the sort itself, in numpy, is not counted). The ratios use the faster of the two.
    t0 = time.perf_counter()
    order = morton_order(pos)
    res["sort_s"] = time.perf_counter() - t0
    best = float("inf")
    for _ in range(max(1, a.repeat)):
        pcs = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pos[order].astype(np.float64)))
        t0 = time.perf_counter()
        pcs.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(k))
        best = min(best, time.perf_counter() - t0)
    res["o3d_estimate_sorted_s"] = best
    if a.orient:
        t0 = time.perf_counter()
        pcs.orient_normals_consistent_tangent_plane(k)
        res["o3d_orient_s"] = time.perf_counter() - t0
        res["o3d_orient_acc"] = accuracy(np.asarray(pcs.normals), tn[order])
    del pcs

    for label, reported, ingest, store in a.ours:
        o = dict(label=label, reported_s=None if reported == "-" else float(reported),
                 ingest_s=float(ingest))
        o["s"] = o["reported_s"] or ((o["ingest_s"] - a.plain_ingest_seconds)
                                     if a.plain_ingest_seconds is not None else None)
        if store != "-":
            t0 = time.perf_counter()
            rec, man = read_store(store)
            o["store_read_s"] = time.perf_counter() - t0
            o["store_estimated_normals"] = man.get("estimated_normals")
            if "nx" not in rec.dtype.names:
                print(f"{store} holds no normals (fields {man['record_fields']})")
            else:
                p = match(pos, np.stack([rec[c] for c in "xyz"], 1).astype(np.float32))
                if p is None:
                    print(f"{store}: positions do not match the input's exactly: normals not compared")
                else:
                    sn = np.stack([rec[c] for c in ("nx", "ny", "nz")], 1)[p].astype(np.float64)
                    o["acc"] = accuracy(sn, tn)
        res["ours"].append(o)

    mps = lambda s: n / s / 1e6  # noqa: E731
    print(f"{n} points, k = {k}; Open3D {res['open3d']} with OMP_NUM_THREADS={res['omp_num_threads']} "
          f"on {res['cpus']} cpus")
    rows = []
    for o in res["ours"]:
        if o["reported_s"]:
            rows.append((f"scanflow {o['label']}: normals as it reports, best run", o["reported_s"]))
        if a.plain_ingest_seconds is not None:
            rows.append((f"scanflow {o['label']}: whole ingest minus plain ingest",
                         o["ingest_s"] - a.plain_ingest_seconds))
        rows.append((f"scanflow {o['label']}: whole ingest", o["ingest_s"]))
    rows.append(("open3d estimate_normals (fit only), input order", res["o3d_estimate_s"]))
    rows.append((f"open3d estimate_normals (fit only), Morton-sorted, best of {max(1, a.repeat)}",
                 res["o3d_estimate_sorted_s"]))
    est = min(res["o3d_estimate_s"], res["o3d_estimate_sorted_s"])
    if a.orient:
        rows.append(("open3d + orient_normals_consistent_tangent_plane (sorted)",
                     res["o3d_estimate_sorted_s"] + res["o3d_orient_s"]))
    w = max(len(r[0]) for r in rows)
    for name, s in rows:
        print(f"  {name:{w}s} {s:8.2f} s {mps(s):8.2f} M points/s" if s > 0 else f"  {name:{w}s} {s:8.2f} s")
    for j, o in enumerate(res["ours"]):
        if not o["s"] or o["s"] <= 0:
            print(f"scanflow {o['label']}: no usable figure")
            continue
        print(f"ratio scanflow {o['label']}/open3d time: {o['s'] / est:.2f} against estimate_normals "
              "alone (faster order)"
              + (f", {o['s'] / (res['o3d_estimate_sorted_s'] + res['o3d_orient_s']):.3f} against "
                 "estimate + orient" if a.orient else ""))
        verdict = "target met" if n / o["s"] >= 1e6 else "target not met"
        print(f"{'target' if j == 0 else '(for information)'} >= 1 M points/s, {o['label']}: "
              f"{verdict} ({mps(o['s']):.2f} M points/s)")
    print("accuracy (against the exact normals of the synthetic surface):")
    for o in res["ours"]:
        if "acc" in o:
            print(f"  {'scanflow ' + o['label']:36s} {fmt_acc(o['acc'])}")
            e = o.get("store_estimated_normals") or {}
            if e:
                print(f"  {'':36s} (store says: {', '.join(f'{k2} {v}' for k2, v in e.items())})")
    print(f"  {'open3d estimate_normals':36s} {fmt_acc(res['o3d_estimate_acc'])}")
    if a.orient:
        print(f"  {'open3d + orient_consistent_tangent':36s} {fmt_acc(res['o3d_orient_acc'])}")
    if a.json:
        json.dump(res, open(a.json, "w"), indent=1)


if __name__ == "__main__":
    main()
