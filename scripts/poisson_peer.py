"""Screened Poisson reconstruction by a peer, for the benchmarks: PoissonRecon as shipped in
pymeshlab (the default), or Open3D's `create_from_point_cloud_poisson` (`--open3d`), on the
same oriented points (a PLY with normals), at the same depth:

    python3 scripts/poisson_peer.py [--open3d] POINTS.ply OUT.ply DEPTH THREADS
"""
import sys

args = sys.argv[1:]
open3d = args[0] == "--open3d"
if open3d:
    args = args[1:]
src, out, depth, threads = args[0], args[1], int(args[2]), int(args[3])
if open3d:
    import open3d as o3d

    pc = o3d.io.read_point_cloud(src)
    if not pc.has_normals():
        raise SystemExit(f"{src}: no normals")
    mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        pc, depth=depth, n_threads=threads)
    if not o3d.io.write_triangle_mesh(out, mesh, write_ascii=False, compressed=False,
                                      write_vertex_normals=False, write_vertex_colors=False):
        raise SystemExit(f"could not write {out}")
else:
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(src)
    ms.generate_surface_reconstruction_screened_poisson(depth=depth, threads=threads,
                                                        preclean=False)
    ms.save_current_mesh(out, binary=True, save_vertex_normal=False, save_vertex_color=False,
                         save_vertex_quality=False, save_face_color=False,
                         save_face_quality=False)
