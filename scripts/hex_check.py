#!/usr/bin/env python3
"""Independent checker for hexahedral (and tetrahedral) volume meshes.

Usage:
    python3 scripts/hex_check.py MESH [--reference SURFACE_OR_TETMESH] [--samples N]
                                      [--per-hex] [--no-gmsh]

MESH is read with meshio (any format meshio reads: .vtk, .vtu, .mesh, .msh, ...); a .msh
file is also opened with the gmsh Python module, whose own element counts and "minSJ"
quality (gmsh.model.mesh.getElementQualities) are reported beside this script's. The
script prints ONE JSON object on standard output and judges nothing: the caller decides
what passes.

Exit status: 0 when the mesh (and the reference) could be read and everything computed;
0 as well, with {"skipped": "<reason>"}, when numpy or meshio is not installed (nothing is
installed here); 1 with {"error": "<message>"} (and the message on standard error) when a
file cannot be read or the computation fails; 2 for a bad command line.

The JSON object (keys always present unless marked optional):

  file, format           MESH as given, its lower-case extension
  reader                 "meshio <version>", or "gmsh <version> (meshio failed)" when
                         meshio cannot read a .msh file that gmsh can (then "meshio_error"
                         holds meshio's message and everything below is gmsh's mesh)
  points, hexes, tets    counts as meshio reads them (hexahedron, tetra blocks)
  other_cells            {meshio cell type: count} for every other cell type
  cell_data              {name: {"count", "min", "max"}} for each numeric cell field meshio
                         reads (count: values over all cell blocks); {} when gmsh read it
  scaled_jacobian        null without hexahedra, else {"min", "mean", "max", "count_le_0"}
                         over hexes of the per-hex scaled Jacobian (below); with --per-hex
                         also "per_hex": [one value per hex, file order]
  tet_volume             null without tetrahedra, else {"min", "max", "count_le_0"} of the
                         signed volumes det(b-a, c-a, d-a)/6
  gmsh                   null unless MESH is .msh; {"skipped": reason} when the gmsh module
                         is missing (or --no-gmsh); {"error": message} when gmsh could not
                         open it; else {"version", "nodes", "hexes", "tets",
                         "min_sj_hex", "min_sj_tet"} (null where there are no such elements)
                         and, with --per-hex, "min_sj_per_hex" (by ascending element tag).
                         gmsh's "minSJ" is gmsh's own measure, not Verdict's: a bound on the
                         Jacobian determinant over the whole element relative to the
                         element's straight-sided shape, 1 for any parallelepiped (a sheared
                         cube included) and > 0 exactly when the element is valid; it is an
                         independent validity and node-order check, not the same number
  boundary               {"quads", "triangles", "edges", "closed", "open_edges"}: boundary
                         faces are the hex quads (tet triangles) that belong to exactly one
                         hex (tet), compared by vertex index; "edges" counts the distinct
                         edges of the boundary faces, "open_edges" those not in exactly two
                         boundary faces, and "closed" is open_edges == 0 (false when there is
                         no boundary face)
  reference              optional, with --reference only: {"file", "kind" ("tetmesh" or
                         "surface"), "triangles", "samples", "mesh_to_reference":
                         {"max", "mean"}, "reference_to_mesh": {"max", "mean"}, "max",
                         "mean"} (the last two the symmetric values: the larger max, the mean
                         of the two means)

Scaled Jacobian (the Verdict library's hex_scaled_jacobian): the minimum of nine
normalised determinants det(a/|a|, b/|b|, c/|c|). At each of the 8 corners a, b, c are the
three edges leaving the corner, ordered so that the unit cube in VTK order scores +1; at the
centre they are the principal axes X1, X2, X3, each the sum of the four edge vectors of the
hex parallel to one axis of the reference cube (low to high). A determinant with a
zero-length vector counts as 0 (Verdict returns its DBL_MAX for the whole element there).
Hexahedra are in VTK order: v0 v1 v2 v3 the bottom face, counter-clockwise seen from
above, v4..v7 above them. Both the corner table and the axes are derived here from the
reference cube, not copied from any implementation.

Distance to the reference: the reference's boundary is its boundary triangles when it
holds tetrahedra (triangles in one tetrahedron), else its triangles (quads split in two).
The mesh's boundary is its boundary quads, each split into two triangles (and boundary
triangles of tets). Each side is sampled with --samples points, uniform by area with a
fixed seed; "max" also takes every vertex of the sampled side. For each sample the exact
distance to the other side's triangles is computed (candidate triangles found with a k-d
tree), so "max" is a sampled one-sided Hausdorff distance and "mean" the area-weighted mean
distance.
"""

import argparse
import contextlib
import io
import json
import math
import os
import sys

# ----------------------------------------------------------------------------------------
# Reference cube in VTK order, from which every table below is derived.

REF = [
    (0, 0, 0),
    (1, 0, 0),
    (1, 1, 0),
    (0, 1, 0),
    (0, 0, 1),
    (1, 0, 1),
    (1, 1, 1),
    (0, 1, 1),
]


def _hex_edges():
    """The 12 edges of the reference cube: vertex pairs differing in one coordinate."""
    edges = []
    for i in range(8):
        for j in range(i + 1, 8):
            if sum(a != b for a, b in zip(REF[i], REF[j])) == 1:
                edges.append((i, j))
    return edges


def _det3(a, b, c):
    return (
        a[0] * (b[1] * c[2] - b[2] * c[1])
        - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
    )


def _corner_table():
    """For each corner, its three neighbours ordered so that the reference cube's det is +1."""
    edges = _hex_edges()
    table = []
    for i in range(8):
        nb = sorted([j for a, b in edges for j in (a, b) if i in (a, b) and j != i])
        assert len(nb) == 3
        vec = lambda j: [REF[j][k] - REF[i][k] for k in range(3)]  # noqa: E731
        if _det3(vec(nb[0]), vec(nb[1]), vec(nb[2])) < 0:
            nb[1], nb[2] = nb[2], nb[1]
        assert _det3(vec(nb[0]), vec(nb[1]), vec(nb[2])) == 1
        table.append((i, nb[0], nb[1], nb[2]))
    return table


def _axis_edges():
    """For each axis, the 4 edges parallel to it as (low, high) vertex pairs."""
    out = [[], [], []]
    for i, j in _hex_edges():
        k = [a != b for a, b in zip(REF[i], REF[j])].index(True)
        lo, hi = (i, j) if REF[i][k] < REF[j][k] else (j, i)
        out[k].append((lo, hi))
    return out


def _hex_faces():
    """The 6 faces of the reference cube as vertex 4-cycles (orientation irrelevant here)."""
    faces = []
    for k in range(3):
        for v in (0, 1):
            vs = [i for i in range(8) if REF[i][k] == v]
            # order the 4 vertices around the face
            others = [a for a in range(3) if a != k]
            ring = sorted(
                vs,
                key=lambda i: math.atan2(REF[i][others[1]] - 0.5, REF[i][others[0]] - 0.5),
            )
            faces.append(tuple(ring))
    return faces


TET_FACES = [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]


def emit(obj, code=0):
    print(json.dumps(obj, allow_nan=False, default=_json_default))
    sys.exit(code)


def _json_default(x):
    try:
        return x.item()
    except AttributeError:
        raise TypeError(f"not JSON serialisable: {type(x)}")


def meshio_read(meshio, path):
    """meshio.read, its messages kept off standard output and its sys.exit made an error."""
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
            return meshio.read(path)
    except SystemExit:
        raise RuntimeError(" ".join(buf.getvalue().split()) or "meshio gave up") from None


def fail(msg):
    print(f"hex_check: {msg}", file=sys.stderr)
    emit({"error": msg}, 1)


def finite_or_none(x):
    x = float(x)
    return x if math.isfinite(x) else None


# ----------------------------------------------------------------------------------------


def scaled_jacobians(np, pts, hexes):
    """Per-hex Verdict scaled Jacobian (see the module docstring)."""
    c = pts[hexes]  # (n, 8, 3)
    dets = []

    def ndet(a, b, cc):
        la = np.linalg.norm(a, axis=1)
        lb = np.linalg.norm(b, axis=1)
        lc = np.linalg.norm(cc, axis=1)
        d = np.einsum("ij,ij->i", a, np.cross(b, cc))
        den = la * lb * lc
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.where(den > 0, d / np.where(den > 0, den, 1.0), 0.0)
        return v

    for o, p, q, r in _corner_table():
        dets.append(ndet(c[:, p] - c[:, o], c[:, q] - c[:, o], c[:, r] - c[:, o]))
    axes = []
    for k in range(3):
        axes.append(sum(c[:, hi] - c[:, lo] for lo, hi in _axis_edges()[k]))
    dets.append(ndet(axes[0], axes[1], axes[2]))
    return np.min(np.stack(dets, axis=1), axis=1)


def boundary(np, hexes, tets):
    """Boundary quads and triangles (in one cell), edges, closedness."""
    faces = []
    for cells, local in ((hexes, _hex_faces()), (tets, TET_FACES)):
        if len(cells) == 0:
            continue
        count = {}
        first = {}
        for cell in cells.tolist():
            for f in local:
                verts = tuple(cell[i] for i in f)
                key = tuple(sorted(verts))
                count[key] = count.get(key, 0) + 1
                first.setdefault(key, verts)
        faces.extend(first[k] for k, n in count.items() if n == 1)
    edges = {}
    for f in faces:
        for i in range(len(f)):
            e = tuple(sorted((f[i], f[(i + 1) % len(f)])))
            edges[e] = edges.get(e, 0) + 1
    open_edges = sum(1 for n in edges.values() if n != 2)
    quads = [f for f in faces if len(f) == 4]
    tris = [f for f in faces if len(f) == 3]
    info = {
        "quads": len(quads),
        "triangles": len(tris),
        "edges": len(edges),
        "closed": bool(faces) and open_edges == 0,
        "open_edges": open_edges,
    }
    return info, quads, tris


def triangulate(np, quads, tris):
    out = [(q[0], q[1], q[2]) for q in quads] + [(q[0], q[2], q[3]) for q in quads]
    out += [tuple(t) for t in tris]
    return np.array(out, dtype=np.int64).reshape(-1, 3)


def cells_of(mesh, name):
    import numpy as np

    blocks = [c.data for c in mesh.cells if c.type == name]
    if not blocks:
        return np.zeros((0, {"hexahedron": 8, "tetra": 4, "triangle": 3, "quad": 4}[name]), int)
    return np.concatenate(blocks).astype(np.int64)


# ----------------------------------------------------------------------------------------
# Distances between triangle sets.


def sample_triangles(np, pts, tris, n, rng):
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    total = area.sum()
    if total <= 0 or n <= 0:
        return np.zeros((0, 3))
    pick = rng.choice(len(tris), size=n, p=area / total)
    u = rng.random(n)
    v = rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return a[pick] + u[:, None] * (b[pick] - a[pick]) + v[:, None] * (c[pick] - a[pick])


def point_triangle_distance(np, p, a, b, c):
    """Exact distances from points p to triangles (a, b, c), row by row (Ericson, RTCD 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    # interior by default
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        den = np.where(den == 0, 1.0, den)
        v = vb / den
        w = vc / den
        q = a + ab * v[:, None] + ac * w[:, None]
        # edge regions
        m_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        t = (d4 - d3) / np.where((d4 - d3) + (d5 - d6) == 0, 1.0, (d4 - d3) + (d5 - d6))
        q = np.where(m_bc[:, None], b + (c - b) * t[:, None], q)
        m_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        t = d2 / np.where(d2 - d6 == 0, 1.0, d2 - d6)
        q = np.where(m_ac[:, None], a + ac * t[:, None], q)
        m_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        t = d1 / np.where(d1 - d3 == 0, 1.0, d1 - d3)
        q = np.where(m_ab[:, None], a + ab * t[:, None], q)
    # vertex regions last (they take precedence)
    q = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, q)
    q = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, q)
    q = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, q)
    return np.linalg.norm(p - q, axis=1)


def distances_to(np, cKDTree, query, pts, tris, rng):
    """Exact distance from each query point to the nearest of triangles `tris` of `pts`.

    An upper bound per query comes from a dense sample of the triangles; the candidates are
    then the triangles whose bounding sphere (centroid, radius) reaches within that bound,
    found with one k-d tree of centroids per power-of-two class of radii (so that a few
    large triangles do not make every triangle a candidate everywhere).
    """
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    cen = (a + b + c) / 3.0
    rad = np.max(np.stack([np.linalg.norm(x - cen, axis=1) for x in (a, b, c)], axis=1), axis=1)
    dense = np.concatenate(
        [pts[np.unique(tris)], cen, sample_triangles(np, pts, tris, 4 * len(tris), rng)]
    )
    upper, _ = cKDTree(dense).query(query)
    with np.errstate(divide="ignore"):
        cls = np.floor(np.log2(np.maximum(rad, 1e-300))).astype(np.int64)
    classes = []
    for k in np.unique(cls):
        idx = np.nonzero(cls == k)[0]
        classes.append((idx, cKDTree(cen[idx]), rad[idx].max()))
    out = np.minimum(upper, np.inf)
    step = 4096
    for s in range(0, len(query), step):
        q = query[s : s + step]
        best = out[s : s + step].copy()
        for idx, tree, rmax in classes:
            cand = tree.query_ball_point(q, best + rmax + 1e-12)
            qi = np.repeat(np.arange(len(q)), [len(x) for x in cand])
            if len(qi) == 0:
                continue
            ti = idx[np.fromiter((t for x in cand for t in x), dtype=np.int64, count=len(qi))]
            d = point_triangle_distance(np, q[qi], a[ti], b[ti], c[ti])
            np.minimum.at(best, qi, d)
        out[s : s + step] = best
    return out


def reference_distance(np, args, pts, mesh_tris, meshio):
    try:
        from scipy.spatial import cKDTree
    except ImportError:
        return {"skipped": "scipy is not installed (needed for --reference)"}
    try:
        ref = meshio_read(meshio, args.reference)
    except Exception as e:  # noqa: BLE001
        fail(f"{args.reference}: cannot read the reference with meshio: {e}")
    rpts = np.asarray(ref.points, dtype=float)[:, :3]
    rtets = cells_of(ref, "tetra")
    if len(rtets):
        kind = "tetmesh"
        _, _, rtri = boundary(np, np.zeros((0, 8), int), rtets)
        rtris = np.array(rtri, dtype=np.int64).reshape(-1, 3)
    else:
        kind = "surface"
        rtris = triangulate(np, [tuple(q) for q in cells_of(ref, "quad").tolist()], cells_of(ref, "triangle").tolist())
    if len(rtris) == 0:
        fail(f"{args.reference}: the reference holds no triangles, quads or tetrahedra")
    if len(mesh_tris) == 0:
        fail(f"{args.mesh}: the mesh has no boundary faces to compare with the reference")
    rng = np.random.default_rng(12345)
    out = {"file": args.reference, "kind": kind, "triangles": int(len(rtris)), "samples": args.samples}
    sides = []
    for name, (sp, st), (tp, tt) in (
        ("mesh_to_reference", (pts, mesh_tris), (rpts, rtris)),
        ("reference_to_mesh", (rpts, rtris), (pts, mesh_tris)),
    ):
        samples = sample_triangles(np, sp, st, args.samples, rng)
        verts = sp[np.unique(st)]
        d_s = distances_to(np, cKDTree, samples, tp, tt, rng) if len(samples) else np.zeros(0)
        d_v = distances_to(np, cKDTree, verts, tp, tt, rng)
        mx = float(max(d_s.max() if len(d_s) else 0.0, d_v.max()))
        mean = float(d_s.mean()) if len(d_s) else float(d_v.mean())
        out[name] = {"max": mx, "mean": mean}
        sides.append((mx, mean))
    out["max"] = max(s[0] for s in sides)
    out["mean"] = 0.5 * (sides[0][1] + sides[1][1])
    return out


# ----------------------------------------------------------------------------------------


def gmsh_check(np, path, no_gmsh, per_hex=False):
    """gmsh's view of a .msh file: (report, (points, hexes, tets, other) or None)."""
    if no_gmsh:
        return {"skipped": "--no-gmsh"}, None
    try:
        import gmsh
    except Exception as e:  # noqa: BLE001 (ImportError, or a missing shared library)
        return {"skipped": f"the gmsh Python module is not available: {e}"}, None
    out = {"version": getattr(gmsh, "__version__", "?")}
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.logger.start()
        try:
            gmsh.open(path)
        except Exception as e:  # noqa: BLE001
            log = [m for m in gmsh.logger.get() if "rror" in m]
            return {"error": f"{e}" + (f": {log[-1]}" if log else "")}, None
        tags, coords, _ = gmsh.model.mesh.getNodes()
        out["nodes"] = len(tags)
        index = {int(t): i for i, t in enumerate(tags)}
        pts = np.asarray(coords, dtype=float).reshape(-1, 3)
        cells = {}
        other = {}
        for dim in (0, 1, 2, 3):
            types, etags, enodes = gmsh.model.mesh.getElements(dim=dim)
            for t, e, n in zip(types, etags, enodes):
                t = int(t)
                if t in (4, 5):
                    k = 4 if t == 4 else 8
                    arr = np.array([index[int(x)] for x in n], dtype=np.int64).reshape(-1, k)
                    cells[t] = np.concatenate([cells[t], arr]) if t in cells else arr
                else:
                    name = gmsh.model.mesh.getElementProperties(t)[0]
                    other[name] = other.get(name, 0) + len(e)
        for key, t in (("hexes", 5), ("tets", 4)):
            out[key] = len(cells.get(t, []))
        for key, t in (("min_sj_hex", 5), ("min_sj_tet", 4)):
            e = gmsh.model.mesh.getElementsByType(t)[0]
            if len(e):
                q = gmsh.model.mesh.getElementQualities(list(e), "minSJ")
                out[key] = finite_or_none(min(q))
                if per_hex and t == 5:
                    # by ascending element tag (file order for files written by scanflow)
                    order = np.argsort(np.asarray(e, dtype=np.int64), kind="stable")
                    out["min_sj_per_hex"] = [finite_or_none(q[i]) for i in order]
            else:
                out[key] = None
        hexes = cells.get(5, np.zeros((0, 8), np.int64))
        tets = cells.get(4, np.zeros((0, 4), np.int64))
        return out, (pts, hexes, tets, other)
    except Exception as e:  # noqa: BLE001
        return {"error": f"gmsh failed: {type(e).__name__}: {e}"}, None
    finally:
        gmsh.logger.stop()
        gmsh.finalize()


def main():
    ap = argparse.ArgumentParser(
        description="Independent checker of a hex (or tet) volume mesh; prints one JSON object."
    )
    ap.add_argument("mesh", metavar="MESH")
    ap.add_argument("--reference", metavar="SURFACE_OR_TETMESH")
    ap.add_argument("--samples", type=int, default=20000, help="samples per surface (default 20000)")
    ap.add_argument("--per-hex", action="store_true", help="also list every hex's scaled Jacobian")
    ap.add_argument("--no-gmsh", action="store_true", help="do not open .msh files with gmsh")
    args = ap.parse_args()
    if args.samples < 0:
        ap.error("--samples must be >= 0")

    try:
        import numpy as np
    except ImportError:
        emit({"skipped": "numpy is not installed"})
    try:
        import meshio
    except ImportError:
        emit({"skipped": "meshio is not installed"})

    if not os.path.isfile(args.mesh):
        fail(f"{args.mesh}: no such file")
    if args.reference is not None and not os.path.isfile(args.reference):
        fail(f"{args.reference}: no such file")
    ext = os.path.splitext(args.mesh)[1].lower().lstrip(".")
    gmsh_report, gmsh_mesh = (None, None)
    if ext == "msh":
        gmsh_report, gmsh_mesh = gmsh_check(np, args.mesh, args.no_gmsh, args.per_hex)
    meshio_error = None
    try:
        mesh = meshio_read(meshio, args.mesh)
    except Exception as e:  # noqa: BLE001
        meshio_error = f"{type(e).__name__}: {e}"
        if gmsh_mesh is None:
            fail(f"{args.mesh}: meshio cannot read it: {meshio_error}")
    if meshio_error is None:
        reader = f"meshio {getattr(meshio, '__version__', '?')}"
        pts = np.asarray(mesh.points, dtype=float).reshape(len(mesh.points), -1)
        if pts.shape[1] < 3:  # planar points: z = 0
            pts = np.pad(pts, ((0, 0), (0, 3 - pts.shape[1])))
        pts = pts[:, :3]
        hexes = cells_of(mesh, "hexahedron")
        tets = cells_of(mesh, "tetra")
        other = {}
        for c in mesh.cells:
            if c.type not in ("hexahedron", "tetra"):
                other[c.type] = other.get(c.type, 0) + len(c.data)
        cell_data = {}
        for name, blocks in mesh.cell_data.items():
            try:
                v = np.concatenate([np.asarray(b, dtype=float).reshape(-1) for b in blocks])
            except (TypeError, ValueError):
                continue  # not numeric
            cell_data[name] = {
                "count": int(len(v)),
                "min": finite_or_none(v.min()) if len(v) else None,
                "max": finite_or_none(v.max()) if len(v) else None,
            }
    else:
        reader = f"gmsh {gmsh_report.get('version', '?')} (meshio failed)"
        pts, hexes, tets, other = gmsh_mesh
        cell_data = {}
    for name, cells in (("hexahedron", hexes), ("tetra", tets)):
        if len(cells) and (cells.min() < 0 or cells.max() >= len(pts)):
            fail(f"{args.mesh}: a {name} refers to a point beyond the {len(pts)} points")

    out = {
        "file": args.mesh,
        "format": ext,
        "reader": reader,
        "points": int(len(pts)),
        "hexes": int(len(hexes)),
        "tets": int(len(tets)),
        "other_cells": other,
        "cell_data": cell_data,
        "scaled_jacobian": None,
        "tet_volume": None,
        "gmsh": gmsh_report,
    }
    if meshio_error is not None:
        out["meshio_error"] = meshio_error
    if len(hexes):
        sj = scaled_jacobians(np, pts, hexes)
        out["scaled_jacobian"] = {
            "min": float(sj.min()),
            "mean": float(sj.mean()),
            "max": float(sj.max()),
            "count_le_0": int((sj <= 0).sum()),
        }
        if args.per_hex:
            out["scaled_jacobian"]["per_hex"] = [float(x) for x in sj]
    if len(tets):
        p = pts[tets]
        vol = np.einsum(
            "ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])
        ) / 6.0
        out["tet_volume"] = {
            "min": float(vol.min()),
            "max": float(vol.max()),
            "count_le_0": int((vol <= 0).sum()),
        }
    info, quads, tris = boundary(np, hexes, tets)
    out["boundary"] = info
    if args.reference is not None:
        out["reference"] = reference_distance(np, args, pts, triangulate(np, quads, tris), meshio)
    emit(out)


if __name__ == "__main__":
    try:
        main()
    except SystemExit:
        raise
    except Exception as e:  # noqa: BLE001
        fail(f"failed: {type(e).__name__}: {e}")
