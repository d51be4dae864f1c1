#!/usr/bin/env python3
"""Point-cloud smoothing peers of scanflow's spectral filter, on the same points, measured the same way.

usage: spectral_peers.py POINTS.ply TRUTH.json [--scanflow BIN] [--out DIR]
                         [--peers jet,bilateral,scipy] [--jet-k 12,24,48,96]
                         [--bilateral 24:25,48:25,48:60] [--bilateral-iters 3]
                         [--bilateral-normals pca|input] [--scipy-k 24,48] [--threads 2]

POINTS.ply: a binary PLY with x y z nx ny nz (scanflow synth's output); TRUTH.json: its truth
file. Each run starts from a fresh copy of the points and is timed alone (reading and writing
files excluded), then written as OUT.ply and measured by `scanflow check OUT.ply --truth TRUTH
--json`, the single source of truth for the figures (every point's distance to the exact surface;
rms_rel is the RMS over the bounding-box diagonal, relief_scale the fitted amplitude of the
bumpy sphere's relief: 1 kept, 0 flattened). One JSON line per run on stdout:
  {"peer", "params", "seconds", "cpu_seconds", "points_per_s", "rms_rel", "mean_rel", "p99_rel", "max_rel",
   "relief_scale", "points"}

Peers:
  cgal-jet        CGAL jet_smooth_point_set(k): a degree-2 jet (local polynomial height field)
                  fitted to the k nearest neighbours, each point projected onto its jet
  cgal-bilateral  CGAL bilateral_smooth_point_set(k, sharpness_angle), run --bilateral-iters
                  times (one call is one iteration); it needs normals: by default PCA normals
                  (k = 24, scipy, oriented like the input's), computed before the timer and
                  reported as normals_seconds; --bilateral-normals input hands it synth's exact
                  normals instead (an unfair head start)
  scipy-plane     the simple baseline: cKDTree k nearest neighbours, a PCA plane through them,
                  each point projected onto its plane (numpy, batched eigh)
Threads: CGAL's bindings run these functions on one thread (cpu_seconds, the process's CPU
time, matches seconds on an idle machine, and stays meaningful on a busy one); scipy's k-NN uses
--threads workers, the rest is numpy.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from normals_peer import read_ply_vertices  # noqa: E402

PCA_NORMALS_K = 24
CHUNK = 100_000


def write_ply(path, pos, nrm):
    """Binary little-endian PLY with double x y z nx ny nz."""
    a = np.empty(len(pos), dtype=[(c, "<f8") for c in ("x", "y", "z", "nx", "ny", "nz")])
    for i, c in enumerate("xyz"):
        a[c] = pos[:, i]
        a["n" + c] = nrm[:, i]
    with open(path, "wb") as f:
        f.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(a)).encode())
        for c in ("x", "y", "z", "nx", "ny", "nz"):
            f.write(("property double %s\n" % c).encode())
        f.write(b"end_header\n")
        a.tofile(f)


def pca_planes(pos, k, threads):
    """Centroid and unit normal of the PCA plane of each point's k nearest neighbours."""
    tree = cKDTree(pos)
    cen = np.empty_like(pos)
    nrm = np.empty_like(pos)
    for s in range(0, len(pos), CHUNK):
        _, idx = tree.query(pos[s:s + CHUNK], k=k, workers=threads)
        nb = pos[idx]                                   # (m, k, 3)
        c = nb.mean(axis=1)
        d = nb - c[:, None, :]
        cov = np.einsum("mki,mkj->mij", d, d)
        _, vec = np.linalg.eigh(cov)                    # ascending eigenvalues
        cen[s:s + CHUNK] = c
        nrm[s:s + CHUNK] = vec[:, :, 0]
    return cen, nrm


def orient_like(nrm, ref):
    """Flip each normal to agree with the reference normal's side."""
    flip = np.einsum("ij,ij->i", nrm, ref) < 0
    nrm[flip] *= -1.0
    return nrm


def scipy_plane(pos, ref_nrm, k, threads):
    cen, nrm = pca_planes(pos, k, threads)
    h = np.einsum("ij,ij->i", pos - cen, nrm)
    return pos - h[:, None] * nrm, orient_like(nrm, ref_nrm)


def cgal_point_set(path):
    from CGAL import CGAL_Point_set_3
    ps = CGAL_Point_set_3.Point_set_3()
    ps.read(path)
    if ps.size() == 0:
        raise SystemExit(f"CGAL read no point from {path}")
    return ps


def check(scanflow, out, truth):
    """scanflow check OUT --truth TRUTH --json, parsed; None (with a note) when it fails."""
    r = subprocess.run([scanflow, "check", out, "--truth", truth, "--json"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        print(f"scanflow check {out} failed: {r.stderr.strip()}", file=sys.stderr)
        return None
    return json.loads(r.stdout)


def emit(peer, params, seconds, cpu, n, rep, extra=None):
    line = {"peer": peer, "params": params, "seconds": round(seconds, 4),
            "cpu_seconds": round(cpu, 4),
            "points_per_s": round(n / seconds, 1) if seconds > 0 else None}
    for key in ("rms_rel", "mean_rel", "p99_rel", "max_rel", "relief_scale", "points"):
        line[key] = rep.get(key) if rep else None
    line.update(extra or {})
    print(json.dumps(line), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("points")
    ap.add_argument("truth")
    ap.add_argument("--scanflow", default="target/release/scanflow")
    ap.add_argument("--out", help="directory for the smoothed PLYs (default: a temporary one)")
    ap.add_argument("--peers", default="jet,bilateral,scipy")
    ap.add_argument("--jet-k", default="12,24,48,96")
    ap.add_argument("--bilateral", default="24:25,48:25,48:60", help="k:sharpness_angle,...")
    ap.add_argument("--bilateral-iters", type=int, default=3)
    ap.add_argument("--bilateral-normals", choices=("pca", "input"), default="pca")
    ap.add_argument("--scipy-k", default="24,48")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    peers = set(a.peers.split(","))
    tmp = None
    if a.out:
        os.makedirs(a.out, exist_ok=True)
        out_dir = a.out
    else:
        tmp = tempfile.TemporaryDirectory(prefix="spectral-peers-")
        out_dir = tmp.name
    stem = os.path.splitext(os.path.basename(a.points))[0]
    v = read_ply_vertices(a.points)
    pos = np.stack([v[c].astype(np.float64) for c in "xyz"], axis=1)
    ref_nrm = np.stack([v["n" + c].astype(np.float64) for c in "xyz"], axis=1)
    n = len(pos)

    if "jet" in peers:
        from CGAL.CGAL_Point_set_processing_3 import jet_smooth_point_set
        for k in map(int, a.jet_k.split(",")):
            ps = cgal_point_set(a.points)
            t0, c0 = time.perf_counter(), time.process_time()
            jet_smooth_point_set(ps, k)
            secs, cpu = time.perf_counter() - t0, time.process_time() - c0
            out = os.path.join(out_dir, f"{stem}_jet{k}.ply")
            ps.write(out)
            emit("cgal-jet", {"k": k}, secs, cpu, n, check(a.scanflow, out, a.truth))

    if "bilateral" in peers:
        from CGAL.CGAL_Point_set_processing_3 import bilateral_smooth_point_set
        src, nsecs, ncpu = a.points, 0.0, 0.0
        if a.bilateral_normals == "pca":
            t0, c0 = time.perf_counter(), time.process_time()
            _, nrm = pca_planes(pos, PCA_NORMALS_K, a.threads)
            nrm = orient_like(nrm, ref_nrm)
            nsecs, ncpu = time.perf_counter() - t0, time.process_time() - c0
            src = os.path.join(out_dir, f"{stem}_pca_normals.ply")
            write_ply(src, pos, nrm)
        for spec in a.bilateral.split(","):
            k, angle = spec.split(":")
            k, angle = int(k), float(angle)
            ps = cgal_point_set(src)
            t0, c0 = time.perf_counter(), time.process_time()
            for _ in range(a.bilateral_iters):
                bilateral_smooth_point_set(ps, k, sharpness_angle=angle)
            secs = time.perf_counter() - t0 + nsecs
            cpu = time.process_time() - c0 + ncpu
            out = os.path.join(out_dir, f"{stem}_bilateral{k}_{angle:g}.ply")
            ps.write(out)
            emit("cgal-bilateral",
                 {"k": k, "sharpness_angle": angle, "iterations": a.bilateral_iters,
                  "normals": a.bilateral_normals},
                 secs, cpu, n, check(a.scanflow, out, a.truth),
                 {"normals_seconds": round(nsecs, 4)})

    if "scipy" in peers:
        for k in map(int, a.scipy_k.split(",")):
            t0, c0 = time.perf_counter(), time.process_time()
            p2, n2 = scipy_plane(pos, ref_nrm, k, a.threads)
            secs, cpu = time.perf_counter() - t0, time.process_time() - c0
            out = os.path.join(out_dir, f"{stem}_plane{k}.ply")
            write_ply(out, p2, n2)
            emit("scipy-plane", {"k": k}, secs, cpu, n, check(a.scanflow, out, a.truth))

    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
