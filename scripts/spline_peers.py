#!/usr/bin/env python3
"""Tensor-product B-spline fitting peers of `scanflow fit`, on the same points, same machine.

usage: spline_peers.py POINTS.ply --tolerance T|P%
                       [--peers scipy-smooth,scipy-bisplrep,occ-approx,occ-interp]
                       [--grid 64,128,256] [--occ-degmax 3] [--attempts 4] [--timeout 300]
                       [--scanflow BIN] [--threads 2] [--out DIR] [--json]

POINTS.ply: scattered height-field points (x y z, e.g. `scanflow synth heightfield`). The tolerance
is absolute (input units) or P% of the diagonal of the points' bounding box (what `scanflow fit
--tolerance P%` means). Every peer runs in its own Python subprocess under a wall-clock limit
(--timeout seconds each), so a hang or a crash inside FITPACK or OpenCascade becomes a row saying
"timeout" or "crashed" instead of stopping the comparison.

Peers (all bicubic):
  scipy-smooth    scipy.interpolate.SmoothBivariateSpline(x, y, z, s=S): FITPACK surfit, knots
                  placed by the routine until the sum of squared residuals is at most S. S starts at
                  n (T/3)^2 (an RMS of a third of the tolerance) and is divided by 8 while the
                  largest residual exceeds T, at most --attempts times. FITPACK's own failures
                  (ier > 0, e.g. "the required storage space exceeds the available storage space",
                  "s too small") are reported as they come, with the attempt they ended.
  scipy-bisplrep  scipy.interpolate.bisplrep (the same surfit with FITPACK's default knot
                  estimates nxest = nyest = 3 + sqrt(n/2)), same s schedule, ier and message kept.
  occ-approx      OpenCascade GeomAPI_PointsToBSplineSurface.Init(Z, X0, dX, Y0, dY, 3, DegMax, C2,
                  Tol3D = T / 2) on an N x N grid of heights resampled from the points (scipy
                  griddata, linear, nearest value outside the convex hull), for each N of --grid.
                  DegMax is --occ-degmax, 3 by default (bicubic like the others). OpenCascade's
                  own default, 8, checks Tol3D only at the grid nodes and oscillates between
                  them: on 100K standard height-field points, grids 64 and 128 gave degree 7-8
                  surfaces 800 units (the diagonal is 2.9) off at points near the corners.
  occ-interp      GeomAPI_PointsToBSplineSurface.Interpolate(Z, X0, dX, Y0, dY): the cubic
                  interpolant of the same grid ((N + 2)^2 control points).
Deviation: at every input point, the vertical residual |S(x, y) - z|. For scipy that is the
spline's value; for OpenCascade it is exact too, since these constructors parameterise the surface
by the plane itself (S(U, V) = (U, V, Z(U, V))). The vertical residual is never smaller than the
distance to the surface (what scanflow's report measures, a Newton foot point); on the standard
height field (slopes up to 0.9) it is at most 1.35 times that distance, on the steepest flanks.
Times: the fit alone for scipy (the attempt shown; total_seconds adds the attempts with larger s
that missed the tolerance); resampling (griddata) plus fit for OpenCascade, both kept in the JSON.
Reading the PLY and measuring the residuals are excluded. Threads: FITPACK and OpenCascade's
approximation run on one thread; scanflow gets --threads (default 2) when it runs.

With --scanflow BIN, when `BIN fit --help` exits 0, scanflow runs too:
`BIN fit POINTS.ply -o OUT.igs --tolerance T --report R.json` (timed, files included); its report
gives the control points (tensor_control_points: those of the exported surfaces, the same kind of
count as the peers'; control_points: of the hierarchy) and deviations. The ratios printed are
scanflow / peer for time and control points against each peer that met the tolerance.

Output: a table on stdout, then one JSON line {"points", "diagonal", "tolerance", "peers": [...],
"scanflow": {...} | null, "ratios": [...]}; with --json only the JSON line.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from normals_peer import read_ply_vertices  # noqa: E402

PEERS = ("scipy-smooth", "scipy-bisplrep", "occ-approx", "occ-interp")


def load_points(path):
    v = read_ply_vertices(path)
    return np.stack([np.asarray(v[c], dtype=np.float64) for c in "xyz"], axis=1)


def parse_tolerance(text, diagonal):
    t = text.strip()
    value = float(t[:-1]) / 100.0 * diagonal if t.endswith("%") else float(t)
    if not (np.isfinite(value) and value > 0):
        raise SystemExit(f"--tolerance {text!r}: expected a positive number or P%")
    return value


def residuals(pred, z):
    r = np.abs(pred - z)
    return float(r.max()), float(np.sqrt(np.mean(r * r)))


# ---------------------------------------------------------------- workers (one per subprocess)

def emit(row):
    print(json.dumps(row), flush=True)


def work_scipy(kind, pts, tol, attempts):
    import warnings
    from scipy.interpolate import BivariateSpline, SmoothBivariateSpline, bisplrep
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    n = len(z)
    s = n * (tol / 3.0) ** 2
    for attempt in range(1, attempts + 1):
        row = {"peer": kind, "attempt": attempt, "s": s}
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                if kind == "scipy-smooth":
                    sp = SmoothBivariateSpline(x, y, z, kx=3, ky=3, s=s)
                    secs = time.perf_counter() - t0
                    tx, ty = sp.get_knots()
                    pred = sp.ev(x, y)
                    ier, msg = None, None
                else:
                    tck, fp, ier, msg = bisplrep(x, y, z, kx=3, ky=3, s=s, full_output=1, quiet=1)
                    secs = time.perf_counter() - t0
                    tx, ty = tck[0], tck[1]
                    pred = BivariateSpline._from_tck(tck).ev(x, y)
            except Exception as e:  # FITPACK raises for storage and argument errors
                row.update(status="error", error=f"{type(e).__name__}: {e}",
                           seconds=time.perf_counter() - t0)
                emit(row)
                return
        warned = [str(w.message).strip().splitlines()[0] for w in caught]
        mx, rms = residuals(pred, z)
        row.update(status="ok", seconds=secs, control_points=(len(tx) - 4) * (len(ty) - 4),
                   knots=[len(tx), len(ty)], max_deviation=mx, rms_deviation=rms, met=mx <= tol,
                   ier=ier, fitpack=(msg.strip().splitlines()[0] if isinstance(msg, str) and ier and ier > 0
                                     else (warned[0] if warned else None)))
        emit(row)
        if mx <= tol:
            return
        s /= 8.0


def resample(pts, n):
    from scipy.interpolate import griddata
    lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
    gx, gy = np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n)
    X, Y = np.meshgrid(gx, gy, indexing="ij")
    Z = griddata(pts[:, :2], pts[:, 2], (X, Y), method="linear")
    holes = ~np.isfinite(Z)
    if holes.any():
        Z[holes] = griddata(pts[:, :2], pts[:, 2], (X[holes], Y[holes]), method="nearest")
    return lo, (hi - lo) / (n - 1), Z


def work_occ(kind, pts, tol, n, degmax):
    from OCP.collections import Array2_double
    from OCP.GeomAPI import GeomAPI_PointsToBSplineSurface
    from OCP.GeomAbs import GeomAbs_C2
    row = {"peer": kind, "grid": n}
    t0 = time.perf_counter()
    lo, d, Z = resample(pts, n)
    t1 = time.perf_counter()
    arr = Array2_double(1, n, 1, n)
    for i in range(n):
        for j in range(n):
            arr.SetValue(i + 1, j + 1, float(Z[i, j]))
    api = GeomAPI_PointsToBSplineSurface()
    if kind == "occ-interp":
        api.Interpolate(arr, float(lo[0]), float(d[0]), float(lo[1]), float(d[1]))
    else:
        api.Init(arr, float(lo[0]), float(d[0]), float(lo[1]), float(d[1]), 3, degmax, GeomAbs_C2, tol / 2.0)
        row["degmax"] = degmax
    if not api.IsDone():
        row.update(status="error", error="IsDone() is false", seconds=time.perf_counter() - t0)
        emit(row)
        return
    surf = api.Surface()
    t2 = time.perf_counter()
    pred = np.fromiter((surf.Value(float(a), float(b)).Z() for a, b in pts[:, :2]), float, len(pts))
    mx, rms = residuals(pred, pts[:, 2])
    row.update(status="ok", seconds=t2 - t0, resample_seconds=t1 - t0, fit_seconds=t2 - t1,
               control_points=surf.NbUPoles() * surf.NbVPoles(),
               degree=[surf.UDegree(), surf.VDegree()], max_deviation=mx, rms_deviation=rms,
               met=mx <= tol)
    emit(row)


def worker(args):
    pts = np.load(args.worker_points)
    if args.worker.startswith("scipy"):
        work_scipy(args.worker, pts, args.worker_tol, args.attempts)
    else:
        work_occ(args.worker, pts, args.worker_tol, args.worker_grid, args.occ_degmax)


# ---------------------------------------------------------------- driver

def run_peer(npy, peer, tol, grid, args):
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", peer, "--worker-points", npy,
           "--worker-tol", repr(tol), "--worker-grid", str(grid or 0), "--attempts", str(args.attempts),
           "--occ-degmax", str(args.occ_degmax),
           "--tolerance", "1"]
    t0 = time.perf_counter()
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
        out, err, rc = r.stdout, r.stderr, r.returncode
        timed_out = False
    except subprocess.TimeoutExpired as e:
        out = e.stdout.decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
        err, rc, timed_out = "", None, True
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    last = rows[-1] if rows else {"peer": peer, "grid": grid} if grid else {"peer": peer}
    last["attempts"] = [{k: r.get(k) for k in ("s", "seconds", "control_points", "max_deviation", "status",
                                                "fitpack", "error")} for r in rows] if peer.startswith("scipy") else None
    if timed_out:
        last = dict(last, status="timeout", met=False,
                    note=f"no result within {args.timeout:g} s"
                         + (f" (after {len(rows)} finished attempt(s))" if rows else ""))
    elif rc != 0:
        tail = (err.strip().splitlines() or ["?"])[-1]
        last = dict(last, status="crashed", met=False, note=f"exit {rc}: {tail}")
    if peer.startswith("scipy") and rows:
        last["total_seconds"] = sum(r.get("seconds") or 0.0 for r in rows)
    last["wall_seconds"] = time.perf_counter() - t0
    return last


def run_scanflow(binary, ply, tol_arg, out_dir, threads):
    try:
        h = subprocess.run([binary, "fit", "--help"], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if h.returncode != 0:
        return None
    quiet = ["--progress", "none"] if "--progress" in h.stdout else []
    igs, rep = os.path.join(out_dir, "scanflow.igs"), os.path.join(out_dir, "scanflow.json")
    t0 = time.perf_counter()
    r = subprocess.run([binary, "fit", ply, "-o", igs, "--tolerance", tol_arg, "--report", rep,
                        "--threads", str(threads)] + quiet, capture_output=True, text=True)
    secs = time.perf_counter() - t0
    if r.returncode != 0:
        return {"peer": "scanflow", "status": "error", "seconds": secs,
                "note": (r.stderr.strip().splitlines() or ["?"])[-1]}
    with open(rep) as f:
        report = json.load(f)
    return {"peer": "scanflow", "status": "ok", "seconds": secs,
            "control_points": report.get("tensor_control_points"),
            "hierarchy_control_points": report.get("control_points"),
            "max_deviation": report.get("max_deviation"), "rms_deviation": report.get("rms_deviation"),
            "met": report.get("met"), "surfaces": report.get("surfaces"), "levels": report.get("levels")}


def table(rows, tol):
    fmt = "{:<15} {:>6} {:>9} {:>10} {:>11} {:>11} {:>5}  {}"
    lines = [fmt.format("peer", "grid", "seconds", "ctrl_pts", "max_dev/T", "rms_dev/T", "met", "note")]
    f = lambda v, p: "-" if v is None else format(v, p)  # noqa: E731
    for r in rows:
        note = r.get("note") or r.get("error") or r.get("fitpack") or ""
        if r.get("fit_seconds") is not None and not note:
            note = f"resample {r['resample_seconds']:.2f} s, fit {r['fit_seconds']:.2f} s, degree {r['degree']}"
        if r.get("peer", "").startswith("scipy") and r.get("attempts"):
            note = (f"s={r.get('s', 0):.3g}, {len(r['attempts'])} attempt(s) "
                    f"{r.get('total_seconds', 0):.1f} s in all" + (f"; {note}" if note else ""))
        md, rd = r.get("max_deviation"), r.get("rms_deviation")
        lines.append(fmt.format(r["peer"], f(r.get("grid"), "d"), f(r.get("seconds"), ".2f"),
                                f(r.get("control_points"), "d"), f(md / tol if md is not None else None, ".3f"),
                                f(rd / tol if rd is not None else None, ".3f"),
                                {True: "yes", False: "no"}.get(r.get("met"), "-"), note[:70]))
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("points", nargs="?")
    ap.add_argument("--tolerance", required=True)
    ap.add_argument("--peers", default=",".join(PEERS))
    ap.add_argument("--grid", default="64,128,256")
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--attempts", type=int, default=4)
    ap.add_argument("--occ-degmax", type=int, default=3)
    ap.add_argument("--scanflow")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--worker-points", help=argparse.SUPPRESS)
    ap.add_argument("--worker-tol", type=float, help=argparse.SUPPRESS)
    ap.add_argument("--worker-grid", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args)
        return
    if not args.points:
        ap.error("POINTS.ply is required")
    peers = [p for p in args.peers.split(",") if p]
    unknown = [p for p in peers if p not in PEERS]
    if unknown:
        ap.error(f"unknown peer(s) {unknown}: expected some of {','.join(PEERS)}")
    pts = load_points(args.points)
    diagonal = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    tol = parse_tolerance(args.tolerance, diagonal)
    out_dir = args.out or tempfile.mkdtemp(prefix="spline-peers-")
    os.makedirs(out_dir, exist_ok=True)
    npy = os.path.join(out_dir, "points.npy")
    np.save(npy, pts)
    rows = []
    for peer in peers:
        grids = [int(g) for g in args.grid.split(",")] if peer.startswith("occ") else [None]
        for g in grids:
            rows.append(run_peer(npy, peer, tol, g, args))
    sf = run_scanflow(args.scanflow, args.points, args.tolerance, out_dir, args.threads) \
        if args.scanflow else None
    ratios = []
    if sf and sf.get("status") == "ok":
        for r in rows:
            if r.get("status") == "ok" and r.get("met"):
                ratios.append({"peer": r["peer"], "grid": r.get("grid"),
                               "time": sf["seconds"] / r["seconds"] if r.get("seconds") else None,
                               "control_points": (sf["control_points"] / r["control_points"]
                                                  if sf.get("control_points") and r.get("control_points")
                                                  else None)})
    if not args.json:
        print(f"{len(pts)} points, diagonal {diagonal:.6g}, tolerance {tol:.6g} ({args.tolerance}); "
              f"deviations are vertical residuals, over T")
        print(table(rows + ([sf] if sf else []), tol))
        for q in ratios:
            g = f" N={q['grid']}" if q["grid"] else ""
            t = "-" if q["time"] is None else f"{q['time']:.3g}"
            c = "-" if q["control_points"] is None else f"{q['control_points']:.3g}"
            print(f"scanflow / {q['peer']}{g}: time {t}, control points {c}")
        if args.scanflow and sf is None:
            print(f"note: {args.scanflow} has no 'fit' command yet: peers only")
    print(json.dumps({"points": len(pts), "diagonal": diagonal, "tolerance": tol,
                      "tolerance_arg": args.tolerance, "peers": rows, "scanflow": sf, "ratios": ratios}))


if __name__ == "__main__":
    main()
