#!/usr/bin/env bash
# Normal estimation throughput: scanflow against Open3D on the same points, same machine, same run.
#
# What it measures (issue 5): POINTS samples of the bumpy sphere (scanflow synth, noise 0.001),
# written once with their exact normals (b.ply) and once as bare x y z (b_nonormals.ply). Timed:
#   scanflow ingest b_nonormals.ply --normals estimate   (plane fits + orientation, out of core)
#       "default":  --neighbours 20, which scanflow grows in cells where noise dominates the fits
#       "fixed-k":  --fixed-neighbours, exactly 20 everywhere: like for like with Open3D
#                   (only when the binary has the flag)
#     the figure is the one scanflow prints ("estimated normals for N points in S s"), else
#     the difference below; the target is judged on "default"
#   scanflow ingest b.ply --normals use                  (the same ingest without estimation: the
#                                                          baseline for that difference)
#   Open3D estimate_normals(KDTreeSearchParamKNN(20))    (fit only; input order and Morton-sorted)
#   Open3D orient_normals_consistent_tangent_plane(20)   (ORIENT=auto: when memory allows,
#                                                          ~2.6 KB/point; minutes at 2M points)
# with THREADS threads for both (scanflow --threads, OMP_NUM_THREADS for Open3D), and points/s
# and ratios printed. The stores are read back and both tools' normals are compared with the
# exact ones (angle, inward fraction).
# Target: scanflow >= 1 M points/s on this 2-core machine. The script fails only when something
# does not run; it prints "target met" / "target not met".
#
# usage: scripts/bench_normals.sh [POINTS=2000000]
#   THREADS=2  K=20  ORIENT=auto|1|0
#   REPEAT=3       best of REPEAT timings for scanflow and for Open3D's estimate_normals (sorted)
#   BUILD=0        use the existing target/release/scanflow (default: cargo build --release first)
#   SCANFLOW=PATH  binary to measure (implies BUILD=0)
#   KEEP=DIR       keep the points, stores and logs in DIR
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/peer_env.sh
export PYTHONDONTWRITEBYTECODE=1   # no __pycache__ in scripts/
N=${1:-2000000}
THREADS=${THREADS:-2}
[[ $N =~ ^[0-9]+$ ]] || { echo "usage: $0 [POINTS]" >&2; exit 2; }
K=${K:-20}
REPEAT=${REPEAT:-3}
ORIENT=${ORIENT:-auto}

# --- Python side: Open3D, numpy (zstandard optional: the zstd command reads the store too)
need_open3d numpy

# --- scanflow
scanflow_bin ingest

if [ -n "${KEEP:-}" ]; then TMP=$KEEP; mkdir -p "$TMP"; rm -rf "$TMP"/store_*
else TMP=$(mktemp -d -t scanflow-normals-XXXX); trap 'rm -rf "$TMP"' EXIT; fi

# run LABEL CMD...: "wall_s peak_KiB user_s sys_s" into $TMP/LABEL.time, stdout to $TMP/LABEL.out,
# stderr to $TMP/LABEL.log
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
field() { awk -v i="$2" '{print $i}' "$TMP/$1.time"; }
mib() { local k; k=$(field "$1" 2); [ "$k" = - ] && echo "?" || echo $((k / 1024)); }

echo "$N points (bumpy sphere, noise 0.001), k = $K, $THREADS threads, $(nproc) cores; scratch $TMP"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?) (a busy machine slows both sides)"
if [ ! -f "$TMP/b.ply" ] || [ ! -f "$TMP/b_nonormals.ply" ]; then
  "$BIN" synth bumpy --points "$N" --noise 0.001 -o "$TMP/b.ply" --progress none > /dev/null
  python3 -c 'import sys; sys.path.insert(0, "scripts")
from normals_peer import read_ply_vertices, write_xyz_ply
write_xyz_ply(sys.argv[2], read_ply_vertices(sys.argv[1]))' "$TMP/b.ply" "$TMP/b_nonormals.ply"
fi
cat "$TMP/b.ply" "$TMP/b_nonormals.ply" > /dev/null   # warm page cache

run plain "$BIN" ingest "$TMP/b.ply" -o "$TMP/store_plain" --normals use --threads "$THREADS" --progress none
# scanflow modes: "default" (what a user gets: --neighbours K, grown where noise dominates, when
# the binary does that) and "fixed-k" (--fixed-neighbours: exactly K everywhere, like Open3D)
modes=(default)
"$BIN" ingest --help | grep -q -- '--fixed-neighbours' && modes+=(fixed-k)
peer_ours=()
for mode in "${modes[@]}"; do
  extra=(); [ "$mode" = fixed-k ] && extra=(--fixed-neighbours)
  # best of REPEAT runs (a shared machine is noisy); the figure parsed from the last line like
  # "estimated normals for N points in S s (X M points/s ...)", defensively
  best_s="" best_wall="" best_i=1 all_runs=""
  for i in $(seq "$REPEAT"); do
    rm -rf "$TMP/store_$mode"
    run "${mode}_$i" "$BIN" ingest "$TMP/b_nonormals.ply" -o "$TMP/store_$mode" --normals estimate \
      --neighbours "$K" "${extra[@]}" --threads "$THREADS" --progress json
    s_i=$(sed -n 's/.*estimated normals for \([0-9][0-9]*\) points in \([0-9.][0-9.]*\) *s.*/\2/p' "$TMP/${mode}_$i.out" | tail -n 1)
    w_i=$(field "${mode}_$i" 1)
    if [ -z "$best_wall" ] || awk -v a="${s_i:-$w_i}" -v b="${best_s:-$best_wall}" 'BEGIN{exit !(a < b)}'; then
      best_s=$s_i best_wall=$w_i best_i=$i
    fi
    all_runs="$all_runs${all_runs:+, }${s_i:-?} s (whole ingest $w_i s)"
  done
  cp "$TMP/${mode}_$best_i.time" "$TMP/$mode.time"; cp "$TMP/${mode}_$best_i.out" "$TMP/$mode.out"
  echo "scanflow $mode (ingest --normals estimate --neighbours $K${extra[*]:+ ${extra[*]}}), each run: $all_runs"
  echo "  best run said:"
  sed 's/^/    /' "$TMP/$mode.out"
  [ -n "$best_s" ] || echo "  (no 'estimated normals for N points in S s' line: using whole ingest minus plain ingest)"
  echo "  whole ingest $(field "$mode" 1) s, peak RSS $(mib "$mode") MiB, CPU $(field "$mode" 3) s user + $(field "$mode" 4) s sys"
  peer_ours+=(--ours "$mode" "${best_s:--}" "$(field "$mode" 1)" "$TMP/store_$mode")
done
echo "plain ingest (--normals use, of the file with normals): $(field plain 1) s"

case "$ORIENT" in
  auto) avail_kib=$(awk '/MemAvailable/ {print $2}' /proc/meminfo 2>/dev/null || echo 0)
        if [ "$avail_kib" -gt $((N * 4)) ]; then ORIENT=1; else ORIENT=0
          echo "open3d orientation skipped: $((avail_kib / 1024)) MiB available, wants ~$((N * 4 / 1024)) MiB"; fi ;;
esac
peer_args=(--neighbours "$K" --repeat "$REPEAT" "${peer_ours[@]}" --plain-ingest-seconds "$(field plain 1)")
[ "$ORIENT" = 0 ] || peer_args+=(--orient)
echo "running open3d ..."
echo
export OMP_NUM_THREADS=$THREADS
run peer python3 scripts/normals_peer.py "$TMP/b_nonormals.ply" "$TMP/b.ply" "${peer_args[@]}" --json "$TMP/normals_figures.json"
cat "$TMP/peer.out"
echo "open3d process: $(field peer 1) s wall, peak RSS $(mib peer) MiB (python, numpy copies and all)"
echo
echo "fairness: same points, same thread count; fixed-k uses Open3D's k exactly, default grows k"
echo "where noise dominates (more work, better normals: see the accuracy lines). scanflow's figure"
echo "includes orienting the normals (MST propagation here: no viewpoint) and its cell I/O; Open3D's"
echo "estimate_normals is the plane fit alone, in memory. Open3D is timed in the input order"
echo "(random, as synth writes) and Morton-sorted; the ratio uses the faster."
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?)"
