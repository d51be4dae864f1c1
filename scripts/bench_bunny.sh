#!/usr/bin/env bash
# Raw Stanford bunny -> one surface: scanflow against Open3D's pipeline, same points, same run.
#
# What it measures (issue 5): the ten raw range scans of ../shared/data/bunny (no normals), posed
# by bun.conf (p' = R(q)^T p + t, the conjugate rotation; bunny_compare.py prints a check that
# this, and not R p + t, puts the scans on the reference), reconstructed at DEPTH by
#   ours     scanflow reconstruct --conf bun.conf --depth DEPTH (normals estimated, out of core)
#   open3d   estimate_normals(KNN 20) + orient_normals_consistent_tangent_plane(20)
#            + create_from_point_cloud_poisson(depth=DEPTH)            (the peer for the target)
#   o3d-cam  the same with each normal flipped to face its scan's scanner (local +z), the rule
#            scanflow uses for .conf scans (CAMERA=0 skips it and the next)
#   sf-o3dn  scanflow reconstruct --normals use on o3d-cam's oriented points: separates the
#            normals (o3d-cam vs sf-o3dn: same normals, two solvers) from the solver (ours vs
#            sf-o3dn: same solver, two normal estimators)
# Each output is measured against Stanford's zippered mesh (reconstruction/bun_zipper.ply) by
# one function (scripts/bunny_compare.py): mean, RMS, p95, max of ref->out and of out->ref where
# the reference exists (output samples whose closest reference point is not on the reference's
# boundary: bun_zipper has holes in its base), relative to the reference's diagonal; plus
# components, closed/oriented/outward, wall and CPU time, peak RSS, and ratios ours/peer.
# Also `scanflow ingest --conf` of the same scans, read back: its points must be the ones posed in
# Python (printed: farthest distance, ~1e-16), and the share of its normals facing their scanner.
# Target: scanflow's two-sided mean distance no worse than Open3D's. The script fails only when
# something does not run; it prints "target met" / "target not met".
#
# usage: scripts/bench_bunny.sh [DEPTH=8]
#   THREADS=2      threads for both (scanflow --threads, OMP_NUM_THREADS for Open3D)
#   BUILD=0        use the existing target/release/scanflow (default: cargo build --release first)
#   SCANFLOW=PATH  binary to measure (implies BUILD=0)
#   SAMPLES=200000 surface samples per mesh;  CAMERA=0 skips the o3d-cam peer
#   KEEP=DIR       keep the meshes, logs and a JSON of all figures in DIR
#   DATA=DIR       the bunny directory (default ../shared/data/bunny, next to the repository)
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/peer_env.sh
export PYTHONDONTWRITEBYTECODE=1   # no __pycache__ in scripts/
DEPTH=${1:-8}
THREADS=${THREADS:-2}
[[ $DEPTH =~ ^[0-9]+$ ]] || { echo "usage: $0 [DEPTH]" >&2; exit 2; }
SAMPLES=${SAMPLES:-200000}
CAMERA=${CAMERA:-1}
DATA=${DATA:-../shared/data/bunny}
CONF=$DATA/bun.conf
REF=$DATA/reconstruction/bun_zipper.ply
for f in "$CONF" "$REF"; do [ -f "$f" ] || { echo "missing $f (the Stanford bunny, see ../shared/data/README)" >&2; exit 1; }; done

# --- Python side: Open3D (wheels for CPython 3.8-3.12 x86-64), numpy, scipy, plyfile; zstandard
# or the zstd command to read the store back
need_open3d numpy scipy plyfile

# --- scanflow
scanflow_bin reconstruct

if [ -n "${KEEP:-}" ]; then TMP=$KEEP; mkdir -p "$TMP"; rm -rf "$TMP"/bunny_*.ply "$TMP"/bunny_*.ply.work "$TMP/store"
else TMP=$(mktemp -d -t scanflow-bunny-XXXX); trap 'rm -rf "$TMP"' EXIT; fi

# run LABEL CMD...: wall s, peak RSS KiB, user s, sys s into $TMP/LABEL.time; stdout to
# $TMP/LABEL.out, stderr to $TMP/LABEL.log
run() {
  local label=$1; shift
  local t0 t1 rc=0
  if [ -x /usr/bin/time ]; then
    /usr/bin/time -f "%e %M %U %S" -o "$TMP/$label.time" "$@" > "$TMP/$label.out" 2> "$TMP/$label.log" || rc=$?
  else
    t0=$(date +%s.%N); "$@" > "$TMP/$label.out" 2> "$TMP/$label.log" || rc=$?; t1=$(date +%s.%N)
    echo "$(echo "$t1 - $t0" | bc -l) - - -" > "$TMP/$label.time"
  fi
  if [ "$rc" != 0 ]; then
    echo "$label failed (exit $rc): $*" >&2; tail -n 20 "$TMP/$label.log" "$TMP/$label.out" >&2; exit 1
  fi
}

cat "$DATA"/*.ply > /dev/null   # warm page cache for everyone
echo "bunny, depth $DEPTH, $THREADS threads, $(nproc) cores; scratch $TMP"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?) (a busy machine slows both sides)"
echo "running scanflow ..."
run ours "$BIN" reconstruct --conf "$CONF" --depth "$DEPTH" --threads "$THREADS" \
  -o "$TMP/bunny_scanflow.ply" --progress json
echo "  $(tail -n 1 "$TMP/ours.out")"
# the same points as a store, to check that Python poses them exactly as scanflow does
run store "$BIN" ingest --conf "$CONF" -o "$TMP/store" --normals estimate --threads "$THREADS" --progress none
echo "  $(grep 'estimated normals' "$TMP/store.out" || true)"
export OMP_NUM_THREADS=$THREADS
echo "running open3d (tangent-plane orientation) ..."
run open3d python3 scripts/bunny_peer.py "$CONF" "$DEPTH" "$TMP/bunny_open3d.ply" --orient tangent
runs=(--run scanflow "$TMP/bunny_scanflow.ply" "$TMP/ours.time"
      --run open3d "$TMP/bunny_open3d.ply" "$TMP/open3d.time" "$TMP/open3d.out")
if [ "$CAMERA" != 0 ]; then
  echo "running open3d (scanner-facing orientation) ..."
  run o3dcam python3 scripts/bunny_peer.py "$CONF" "$DEPTH" "$TMP/bunny_o3dcam.ply" --orient camera \
    --save-points "$TMP/o3dcam_points.ply"
  runs+=(--run o3d-cam "$TMP/bunny_o3dcam.ply" "$TMP/o3dcam.time" "$TMP/o3dcam.out")
  echo "running scanflow on o3d-cam's normals ..."
  run sfo3dn "$BIN" reconstruct "$TMP/o3dcam_points.ply" --normals use --depth "$DEPTH" \
    --threads "$THREADS" -o "$TMP/bunny_sf_o3dn.ply" --progress json
  runs+=(--run sf-o3dn "$TMP/bunny_sf_o3dn.ply" "$TMP/sfo3dn.time")
fi
echo "measuring against $(basename "$REF") ..."
echo
python3 scripts/bunny_compare.py --conf "$CONF" --reference "$REF" --samples "$SAMPLES" --store "$TMP/store" \
  --json "$TMP/bunny_figures.json" "${runs[@]}"
echo
echo "fairness: same posed points, same depth (2^DEPTH cells across 1.1x the bounding cube), same"
echo "thread count; Open3D's time is its whole Python process (import and PLY reading included;"
echo "its stage times are listed), scanflow's its whole process (reading, normals, solve, mesh)."
echo "Open3D's Poisson is PoissonRecon (screened); neither output is trimmed by density."
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?)"
