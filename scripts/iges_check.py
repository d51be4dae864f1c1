#!/usr/bin/env python3
"""Independent check of an IGES surface file against points: OpenCascade and gmsh.

    iges_check.py SURF.igs POINTS.ply|POINTS.xyz [--json] [--no-gmsh]

OpenCascade (the `cadquery-ocp` package, module OCP) reads SURF.igs with its own IGES reader
(IGESControl_Reader, every root transferred) and gathers every face's surface. Every point of
POINTS (a PLY with x y z as float or double, through plyfile; or text whose first three
columns are x y z) is projected onto each surface with GeomAPI_ProjectPointOnSurf
(initialised once per surface on its parameter range with the tree algorithm, then Perform
per point; the lower distance of the orthogonal projections found). Surfaces are visited nearest bounding box
first and skipped once their box is farther than the best distance so far. A point with no
orthogonal projection on any surface is measured against a dense sample of the surfaces
(a grid of 257 x 257 parameters, every boundary at 4097) and counted in `no_projection`.
A point nearer to a sample of the surfaces' boundaries (4097 parameters per edge, 1025 beyond
16 surfaces) than to its projection lies beyond an edge: it takes the sample's distance
(an upper bound, within the sampling's chord error) and is counted in `boundary_nearest`.

gmsh (the `gmsh` package) then opens the file on its own (it imports IGES through its own
OpenCascade build); its log's warnings and errors, its surface count and, per surface, the
points at the four corners of its parametrisation are reported, so a caller can check that
the coordinates came back unscaled.

Prints one JSON object (--json) or a short summary:
  {"surfaces", "points", "max", "rms", "mean", "no_projection", "boundary_nearest", "local_nearer",
   "seconds_projection", "seconds_boundary",
   "points_per_second", "occ_bspline": [{"degree", "poles", "knots", "weights_one",
   "range"}...], "gmsh": {"ok", "warnings", "entities", "corners"}}
`poles` are [u][v][xyz], `knots` the full knot sequences (multiplicities expanded) along u
and v.
"""

import argparse
import json
import math
import os
import sys
import time

import numpy as np


def read_points(path):
    """The points of a PLY (x y z, any numeric type) or of a text file, as an (n, 3) array."""
    with open(path, "rb") as f:
        magic = f.read(3)
    if magic == b"ply":
        from plyfile import PlyData

        v = PlyData.read(path)["vertex"]
        return np.column_stack([np.asarray(v[c], dtype=np.float64) for c in "xyz"])
    pts = np.loadtxt(path, dtype=np.float64, ndmin=2, usecols=(0, 1, 2))
    return pts.reshape(-1, 3)


def _static(cls, name):
    """A static method of an OCP class: `Name_s` in most OCP builds, `Name` in some."""
    return getattr(cls, name + "_s", None) or getattr(cls, name)


def occ_surfaces(path):
    """Every face's surface of the IGES file, as OpenCascade reads it, with its face."""
    from OCP.BRep import BRep_Tool
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.IGESControl import IGESControl_Reader
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    reader = IGESControl_Reader()
    if reader.ReadFile(path) != IFSelect_RetDone:
        raise SystemExit(f"{path}: OpenCascade cannot read the file")
    reader.TransferRoots()
    shape = reader.OneShape()
    faces = []
    exp = TopExp_Explorer(shape, TopAbs_FACE)
    while exp.More():
        face = _static(TopoDS, "Face")(exp.Current())
        faces.append((face, _static(BRep_Tool, "Surface")(face)))
        exp.Next()
    return faces


def describe_bspline(surf):
    """Degree, poles, knots of a B-spline surface (None for another kind)."""
    from OCP.GeomAbs import GeomAbs_BSplineSurface
    from OCP.GeomAdaptor import GeomAdaptor_Surface

    ad = GeomAdaptor_Surface(surf)
    if ad.GetType() != GeomAbs_BSplineSurface:
        return None
    bs = ad.BSpline()
    poles = [
        [list(_xyz(bs.Pole(i, j))) for j in range(1, bs.NbVPoles() + 1)]
        for i in range(1, bs.NbUPoles() + 1)
    ]
    uk = bs.UKnotSequence()
    vk = bs.VKnotSequence()
    weights_one = all(
        bs.Weight(i, j) == 1.0
        for i in range(1, bs.NbUPoles() + 1)
        for j in range(1, bs.NbVPoles() + 1)
    )
    return {
        "degree": [bs.UDegree(), bs.VDegree()],
        "poles": poles,
        "knots": [
            [uk.Value(i) for i in range(uk.Lower(), uk.Upper() + 1)],
            [vk.Value(i) for i in range(vk.Lower(), vk.Upper() + 1)],
        ],
        "weights_one": weights_one,
        "range": list(bs.Bounds()),
    }


def _xyz(p):
    return (p.X(), p.Y(), p.Z())


def surface_sample(surf, bounds, n=257, nb=4097):
    """Points of `surf` on a grid of n x n parameters and on its boundary at nb each."""
    u0, u1, v0, v1 = bounds
    out = []
    for u in np.linspace(u0, u1, n):
        for v in np.linspace(v0, v1, n):
            out.append(_xyz(surf.Value(u, v)))
    for t in np.linspace(0.0, 1.0, nb):
        u, v = u0 + t * (u1 - u0), v0 + t * (v1 - v0)
        for uv in ((u, v0), (u, v1), (u0, v), (u1, v)):
            out.append(_xyz(surf.Value(*uv)))
    return np.asarray(out)


def bbox(face):
    """The face's axis-aligned box, as (lo, hi) arrays."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    b = Bnd_Box()
    _static(BRepBndLib, "Add")(face, b)
    return np.array(_xyz(b.CornerMin())), np.array(_xyz(b.CornerMax()))


def project(points, faces):
    """Distance of every point to the nearest surface, and the count without projection."""
    from OCP.Extrema import Extrema_ExtAlgo_Tree
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.gp import gp_Pnt

    projs, boxes, bounds = [], [], []
    for face, surf in faces:
        b = surf.Bounds()
        p = GeomAPI_ProjectPointOnSurf()
        # The tree algorithm samples the surface once here; per point it starts from the
        # nearest sample (same distances as the default gradient algorithm to 1e-15 on
        # points near the surface, five times faster).
        p.Init(surf, b[0], b[1], b[2], b[3], Extrema_ExtAlgo_Tree)
        projs.append(p)
        boxes.append(bbox(face))
        bounds.append(b)
    lo = np.array([b[0] for b in boxes]).reshape(-1, 3)
    hi = np.array([b[1] for b in boxes]).reshape(-1, 3)
    dist = np.full(len(points), math.inf)
    missing = []
    chunk = max(1, 2_000_000 // max(1, len(faces)))
    for c0 in range(0, len(points), chunk):
        q = points[c0 : c0 + chunk]
        # gap[k, s]: distance from point k to surface s's box, a lower bound of its distance.
        g = np.maximum(np.maximum(lo[None] - q[:, None], q[:, None] - hi[None]), 0.0)
        gap = np.sqrt((g**2).sum(axis=2))
        order = np.argsort(gap, axis=1, kind="stable")
        for k in range(len(q)):
            best = math.inf
            pnt = gp_Pnt(*q[k])
            for s in order[k]:
                if gap[k, s] > best:
                    break
                p = projs[s]
                p.Perform(pnt)
                if p.NbPoints() > 0:
                    best = min(best, p.LowerDistance())
            if best == math.inf:
                missing.append(c0 + k)
            dist[c0 + k] = best
    if missing:
        sample = np.vstack([surface_sample(s, b) for (_, s), b in zip(faces, bounds)])
        for k in missing:
            dist[k] = np.sqrt(((sample - points[k]) ** 2).sum(axis=1).min())
    return dist, len(missing)


# Nearest grid samples Newton's method starts from, per point.
STARTS = 8


def grid_sample(surf, per_span=8, least=257, most=2049):
    """Points of `surf` on a grid that follows its knot spans: `per_span` parameters per span
    along each axis (at least `least`, at most `most`), evaluated from the poles and knots
    OpenCascade read (scipy's B-spline basis, vectorised), with the parameters of each point.
    A surface whose control net is finer than the points it was fitted to can carry narrow
    wrinkles that a fixed grid steps over; per-span sampling resolves them."""
    from scipy.interpolate import BSpline

    u0, u1, v0, v1 = surf.Bounds()
    d = describe_bspline(surf)
    if d is None or not d["weights_one"]:
        us, vs = np.linspace(u0, u1, least), np.linspace(v0, v1, least)
        xyz = np.array([[_xyz(surf.Value(a, b)) for b in vs] for a in us])
    else:
        P = np.asarray(d["poles"], dtype=np.float64)
        axes = []
        for t, (lo, hi), p in zip(d["knots"], ((u0, u1), (v0, v1)), d["degree"]):
            t = np.asarray(t, dtype=np.float64)
            spans = int(np.count_nonzero(np.diff(t[p : len(t) - p]) > 0))
            n = int(min(max(least, per_span * spans + 1), most))
            x = np.linspace(lo, hi, n)
            axes.append((x, BSpline.design_matrix(x, t, p).toarray()))
        (us, bu), (vs, bv) = axes
        xyz = np.einsum("ai,ijc,bj->abc", bu, P, bv, optimize=True)
    uu, vv = np.meshgrid(us, vs, indexing="ij")
    return xyz.reshape(-1, 3), np.column_stack([uu.ravel(), vv.ravel()])


def local_from_samples(points, faces, dist):
    """Lower `dist` where Newton's method on OpenCascade's own evaluation of the surface
    (Geom_Surface.D2), started at each of the STARTS nearest samples of the surfaces' grids
    (`grid_sample`: 8 parameters per knot span, at least 257 per axis), finds a nearer foot
    point; how many did. Only points with a sample nearer than their projection are tried:
    elsewhere the projection already beat every sample.

    The tree algorithm of GeomAPI_ProjectPointOnSurf starts from a coarse sampling and can
    settle on a farther local minimum where a surface curls near its edge (seen beyond the
    last points of a fitted patch). Newton on f(u, v) = |S(u, v) - p|^2 / 2 (Hessian
    [S_a.S_b + S_ab.r], the step halved until f falls, kept inside the bounds) from the
    nearest grid sample finds the global minimum whenever the grid resolves the surface's
    folds. Only a smaller distance is taken, so this never reports less than the true one.
    """
    from OCP.gp import gp_Pnt, gp_Vec
    from scipy.spatial import cKDTree

    xyz, owner, params = [], [], []
    for k, (_, surf) in enumerate(faces):
        x, uv = grid_sample(surf)
        xyz.append(x)
        owner.append(np.full(len(x), k))
        params.append(uv)
    xyz, owner, params = np.vstack(xyz), np.concatenate(owner), np.vstack(params)
    starts = min(STARTS, len(xyz))
    d0, idx = cKDTree(xyz).query(points, k=starts)
    d0, idx = d0.reshape(len(points), -1), idx.reshape(len(points), -1)
    P, Du, Dv, Duu, Dvv, Duv = gp_Pnt(), gp_Vec(), gp_Vec(), gp_Vec(), gp_Vec(), gp_Vec()

    def f_at(surf, u, v, q):
        surf.D2(u, v, P, Du, Dv, Duu, Dvv, Duv)
        r = np.array(_xyz(P)) - q
        return r, float(r @ r)

    def newton(surf, u, v, q):
        u0, u1, v0, v1 = surf.Bounds()
        r, f = f_at(surf, u, v, q)
        for _ in range(30):
            su, sv = np.array(_xyz(Du)), np.array(_xyz(Dv))
            suu, svv, suv = np.array(_xyz(Duu)), np.array(_xyz(Dvv)), np.array(_xyz(Duv))
            g = np.array([su @ r, sv @ r])
            h = np.array([[su @ su + suu @ r, su @ sv + suv @ r], [su @ sv + suv @ r, sv @ sv + svv @ r]])
            if np.linalg.det(h) <= 0 or h[0, 0] <= 0:
                h = np.array([[su @ su, su @ sv], [su @ sv, sv @ sv]])
            try:
                step = -np.linalg.solve(h, g)
            except np.linalg.LinAlgError:
                break
            moved = False
            for _ in range(30):
                un = min(max(u + step[0], u0), u1)
                vn = min(max(v + step[1], v0), v1)
                rn, fn = f_at(surf, un, vn, q)
                if fn <= f:
                    moved = abs(un - u) + abs(vn - v) > 1e-15 * (u1 - u0)
                    u, v, r, f = un, vn, rn, fn
                    break
                step = step * 0.5
            # D2 must describe the accepted point for the next step.
            f_at(surf, u, v, q)
            if not moved:
                break
        return math.sqrt(f)

    better = 0
    for i in range(len(points)):
        # Only where a sample is nearer than the projection did the projection miss.
        if not d0[i, 0] < dist[i]:
            continue
        q = points[i]
        best = dist[i]
        for j in idx[i]:
            u, v = params[j]
            best = min(best, newton(faces[owner[j]][1], u, v, q))
        if best < dist[i] - 1e-15:
            dist[i] = best
            better += 1
    return better


def boundary_nearest(points, faces, dist):
    """Lower `dist` where a sample of the surfaces' boundaries is nearer; how many were.

    A point beyond a surface's edge has its nearest surface point on the boundary, where no
    orthogonal projection lands: the projection reports a farther local minimum. Boundary
    samples lie on the surface, so taking the minimum never goes below the true distance.
    """
    from scipy.spatial import cKDTree

    nb = 4097 if len(faces) <= 16 else 1025
    samples = []
    for _, surf in faces:
        u0, u1, v0, v1 = surf.Bounds()
        for t in np.linspace(0.0, 1.0, nb):
            u, v = u0 + t * (u1 - u0), v0 + t * (v1 - v0)
            for uv in ((u, v0), (u, v1), (u0, v), (u1, v)):
                samples.append(_xyz(surf.Value(*uv)))
    # Only a sample nearer than the projection matters: the bound prunes the search.
    bound = float(dist.max()) if len(dist) else 0.0
    d, _ = cKDTree(np.asarray(samples)).query(points, distance_upper_bound=bound)
    nearer = d < dist
    dist[nearer] = d[nearer]
    return int(nearer.sum())


def gmsh_check(path):
    """Open the file in gmsh: ok, warnings and errors from its log, surfaces, corners."""
    import gmsh

    out = {"ok": False, "warnings": [], "entities": 0, "corners": []}
    gmsh.initialize(["gmsh"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.logger.start()
        try:
            gmsh.open(path)
            out["ok"] = True
        except Exception as e:  # gmsh raises a bare Exception carrying its last error
            out["warnings"].append(f"Error: {e}")
        log = gmsh.logger.get()
        gmsh.logger.stop()
        out["warnings"] += [m for m in log if m.startswith(("Warning", "Error"))]
        ents = gmsh.model.getEntities(2)
        out["entities"] = len(ents)
        for dim, tag in ents:
            lo, hi = gmsh.model.getParametrizationBounds(dim, tag)
            uv = [lo[0], lo[1], hi[0], lo[1], lo[0], hi[1], hi[0], hi[1]]
            xyz = gmsh.model.getValue(dim, tag, uv)
            out["corners"].append([list(xyz[i : i + 3]) for i in range(0, 12, 3)])
    finally:
        gmsh.finalize()
    out["ok"] = out["ok"] and not out["warnings"]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("iges")
    ap.add_argument("points")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--no-gmsh", action="store_true", help="skip the gmsh load")
    a = ap.parse_args()

    # OpenCascade and gmsh print to the C stdout: send it to stderr, keep stdout for ours.
    sys.stdout.flush()
    out = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    faces = occ_surfaces(a.iges)
    if not faces:
        raise SystemExit(f"{a.iges}: OpenCascade found no surface")
    points = read_points(a.points)
    t0 = time.perf_counter()
    dist, missing = project(points, faces)
    secs = time.perf_counter() - t0
    t0 = time.perf_counter()
    local = local_from_samples(points, faces, dist)
    edge = boundary_nearest(points, faces, dist)
    secs_edge = time.perf_counter() - t0
    n = len(points)
    res = {
        "surfaces": len(faces),
        "points": n,
        "max": float(dist.max()) if n else 0.0,
        "rms": float(np.sqrt((dist**2).mean())) if n else 0.0,
        "mean": float(dist.mean()) if n else 0.0,
        "no_projection": missing,
        "boundary_nearest": edge,
        "local_nearer": local,
        "seconds_projection": secs,
        "seconds_boundary": secs_edge,
        "points_per_second": n / secs if secs > 0 else None,
        "occ_bspline": [describe_bspline(s) for _, s in faces],
        "gmsh": None if a.no_gmsh else gmsh_check(a.iges),
    }
    if a.json:
        print(json.dumps(res), file=out)
    else:
        print(
            f"{res['surfaces']} surfaces, {n} points: max {res['max']:.6g} "
            f"rms {res['rms']:.6g} mean {res['mean']:.6g}, "
            f"{missing} without projection, {edge} beyond an edge, {res['points_per_second'] or 0:.0f} points/s",
            file=out,
        )
        if res["gmsh"] is not None:
            g = res["gmsh"]
            print(
                f"gmsh: ok {g['ok']}, {g['entities']} surfaces, warnings {g['warnings']}",
                file=out,
            )
    out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
