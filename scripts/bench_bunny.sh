#!/usr/bin/env bash
# The ten raw Stanford bunny scans (no normals) -> one surface, scanflow against Open3D's
# pipeline on the same points (estimate_normals, orient_normals_consistent_tangent_plane,
# create_from_point_cloud_poisson at the same depth), both measured against Stanford's zippered
# mesh. Target: scanflow's two-sided distance no worse than Open3D's.
# usage: scripts/bench_bunny.sh [DEPTH=8]
set -euo pipefail
cd "$(dirname "$0")/.."
depth="${1:-8}"
data=../shared/data/bunny
python3 -m pip install --quiet --disable-pip-version-check open3d plyfile numpy
python3 -c "import open3d" 2>/dev/null || { apt-get install -y -qq libusb-1.0-0 libgomp1 >/dev/null; }
cargo build --release --quiet
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
/usr/bin/time -f "%e %M" -o "$tmp/time" target/release/scanflow reconstruct --conf "$data/bun.conf" \
  --depth "$depth" -o "$tmp/ours.ply" --progress none
read -r secs kib < "$tmp/time"
python3 scripts/bunny_compare.py "$data/bun.conf" "$data/reconstruction/bun_zipper.ply" \
  "$tmp/ours.ply" "$depth" "$secs" "$kib"
