#!/usr/bin/env bash
# Normal estimation throughput: scanflow (k = 20, plane fits and orientation, out of core)
# against Open3D's estimate_normals (KNN 20, no orientation) and
# orient_normals_consistent_tangent_plane on the same points, same machine, same run.
# Target: >= 1 M points/s on a 2-core machine.
# usage: scripts/bench_normals.sh [POINTS=2000000]
set -euo pipefail
cd "$(dirname "$0")/.."
n="${1:-2000000}"
python3 -m pip install --quiet --disable-pip-version-check open3d plyfile numpy
python3 -c "import open3d" 2>/dev/null || { apt-get install -y -qq libusb-1.0-0 libgomp1 >/dev/null; }
cargo build --release --quiet
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
target/release/scanflow synth bumpy --points "$n" --noise 0.001 -o "$tmp/b.ply" --progress none >/dev/null
python3 - "$tmp/b.ply" "$tmp/bare.ply" <<'PY'
import sys, numpy as np, plyfile
v = plyfile.PlyData.read(sys.argv[1])["vertex"]
a = np.empty(len(v), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
for c in "xyz":
    a[c] = v[c]
plyfile.PlyData([plyfile.PlyElement.describe(a, "vertex")]).write(sys.argv[2])
PY
out=$(target/release/scanflow ingest "$tmp/bare.ply" -o "$tmp/store" --normals estimate --progress none)
echo "$out"
ours=$(echo "$out" | sed -n 's/^estimated normals for \([0-9]*\) points in \([0-9.]*\) s.*/\2/p')
python3 - "$tmp/bare.ply" "$n" "$ours" <<'PY'
import sys, time, numpy as np, open3d as o3d, plyfile
v = plyfile.PlyData.read(sys.argv[1])["vertex"]
n, ours = int(sys.argv[2]), float(sys.argv[3])
pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.stack([v[c] for c in "xyz"], 1).astype(float)))
t0 = time.time()
pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(20))
est = time.time() - t0
t0 = time.time()
pc.orient_normals_consistent_tangent_plane(20)
ori = time.time() - t0
print(f"{n} points, k = 20")
print(f"scanflow (fit + orient, out of core): {ours:.2f} s = {n / ours / 1e6:.2f} M points/s")
print(f"open3d estimate_normals:               {est:.2f} s = {n / est / 1e6:.2f} M points/s")
print(f"open3d + orient_consistent_tangent:    {est + ori:.2f} s = {n / (est + ori) / 1e6:.2f} M points/s")
print(f"ratio scanflow/open3d time: {ours / est:.2f} (estimate only), {ours / (est + ori):.3f} (with orientation)")
print("target >= 1 M points/s:", "met" if n / ours >= 1e6 else "not met")
PY
