#!/usr/bin/env bash
# Hierarchical B-spline fitting (issue 15): scanflow fit on scattered height-field points, and
# the tensor-product spline fitters of scipy (FITPACK surfit) and OpenCascade
# (GeomAPI_PointsToBSplineSurface) on the same points, same machine, same run.
#
# What it measures: `scanflow synth heightfield` at SIZES points (default 100K and 1M; 10M too
# with BIG=1, fitted under --mem 512M), noise NOISE. For each size and tolerance in TOLS
# (default 0.1% and 0.01% of the diagonal):
#   scanflow fit IN.ply -o OUT.igs --tolerance T --report R.json --threads THREADS
#     under /usr/bin/time -v: wall seconds, peak RSS, points/s, control points (of the
#     exported tensor surfaces and of the hierarchy), max and RMS deviation (Newton foot points)
#     and whether the tolerance was met, all from the report; skipped, with a note, when the
#     binary has no `fit` command yet
#   scripts/spline_peers.py on the sizes in PEER_SIZES (default 100K and 1M): SmoothBivariateSpline,
#     bisplrep, OpenCascade approximation and interpolation on griddata grids (GRIDS), each in
#     its own subprocess under PEER_TIMEOUT seconds, failures (timeout, FITPACK's storage errors)
#     reported as rows; peer deviations are vertical residuals (>= the distance), see the script
#
# usage: scripts/bench_spline.sh
#   SIZES="100000 1000000"  TOLS="0.1% 0.01%"  NOISE=0  THREADS=2
#   BIG=1            also 10M points, scanflow only (synth + fit at 10M take a while)
#   PEER_SIZES="100000 1000000"  PEER_TIMEOUT=600  GRIDS=64,128,256  PEERS=0 (scanflow only)
#   BUILD=0          use the existing target/release/scanflow;  SCANFLOW=PATH  binary to measure
#   KEEP=DIR         keep points, outputs and logs in DIR
set -euo pipefail
cd "$(dirname "$0")/.."
export PYTHONDONTWRITEBYTECODE=1   # no __pycache__ in scripts/
SIZES=${SIZES:-100000 1000000}
[ "${BIG:-0}" = 0 ] || SIZES="$SIZES 10000000"
TOLS=${TOLS:-0.1% 0.01%}
NOISE=${NOISE:-0}
THREADS=${THREADS:-2}
PEERS=${PEERS:-1}
PEER_SIZES=${PEER_SIZES:-100000 1000000}
PEER_TIMEOUT=${PEER_TIMEOUT:-600}
GRIDS=${GRIDS:-64,128,256}

if [ "$PEERS" != 0 ]; then
  python3 -c 'import scipy.interpolate, numpy, OCP.GeomAPI' 2>/dev/null ||
    python3 -m pip install --quiet --disable-pip-version-check cadquery-ocp scipy numpy plyfile || {
      echo "pip could not install cadquery-ocp scipy numpy (no index reachable? Python $(python3 -V 2>&1))" >&2; exit 1; }
  python3 -c 'import scipy.interpolate, OCP.GeomAPI' || { echo "scipy or OCP does not import" >&2; exit 1; }
fi

if [ -n "${SCANFLOW:-}" ]; then BIN=$SCANFLOW
else
  BIN=$PWD/target/release/scanflow
  [ "${BUILD:-1}" = 0 ] || cargo build --release --quiet
fi
[ -x "$BIN" ] || { echo "no scanflow binary at $BIN" >&2; exit 1; }
HAVE_FIT=1 QUIET=()
"$BIN" fit --help > /dev/null 2>&1 || HAVE_FIT=0
[ "$HAVE_FIT" = 0 ] || ! "$BIN" fit --help | grep -q -- --progress || QUIET=(--progress none)
[ -x /usr/bin/time ] || { echo "needs GNU time at /usr/bin/time (apt-get install time)" >&2; exit 1; }

if [ -n "${KEEP:-}" ]; then TMP=$KEEP; mkdir -p "$TMP"
else TMP=$(mktemp -d -t scanflow-spline-XXXX); trap 'rm -rf "$TMP"' EXIT; fi

echo "sizes: $SIZES; tolerances: $TOLS; noise $NOISE; $THREADS threads, $(nproc) cores; scratch $TMP"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?) (a busy machine slows every side)"
[ "$HAVE_FIT" = 1 ] || echo "note: $BIN has no 'fit' command yet: scanflow rows skipped, peers only"

printf '%-9s %-7s %-9s %9s %10s %11s %10s %10s %11s %11s %4s\n' \
  points tol who seconds points/s peak_MiB ctrl_pts hier_pts max_dev rms_dev met
for n in $SIZES; do
  in=$TMP/hf_$n.ply
  [ -f "$in" ] || "$BIN" synth heightfield --points "$n" --noise "$NOISE" -o "$in" --progress none > /dev/null
  cat "$in" > /dev/null   # warm page cache
  mem=()
  [ "$n" -lt 10000000 ] || mem=(--mem 512M)
  for tol in $TOLS; do
    tag=${n}_$(echo "$tol" | tr -c '0-9.\n' '_')
    if [ "$HAVE_FIT" = 1 ]; then
      if /usr/bin/time -v -o "$TMP/fit_$tag.time" "$BIN" fit "$in" -o "$TMP/fit_$tag.igs" --tolerance "$tol" \
           --report "$TMP/fit_$tag.json" --threads "$THREADS" "${mem[@]}" "${QUIET[@]}" > "$TMP/fit_$tag.log" 2>&1; then
        python3 - "$n" "$tol" "$TMP/fit_$tag.json" "$TMP/fit_$tag.time" <<'EOF'
import json, re, sys
n, tol, rep, tim = sys.argv[1:5]
r = json.load(open(rep))
t = open(tim).read()
wall = re.search(r"Elapsed \(wall clock\) time.*: (.+)", t).group(1).strip().split(":")
secs = sum(float(p) * 60 ** i for i, p in enumerate(reversed(wall)))
rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
f = lambda v, p: "-" if v is None else format(v, p)
print(f"{n:<9} {tol:<7} {'scanflow':<9} {secs:9.2f} {int(n) / secs:10.3g} {rss:11.1f} "
      f"{f(r.get('tensor_control_points'), 'd'):>10} {f(r.get('control_points'), 'd'):>10} "
      f"{f(r.get('max_deviation'), '.3e'):>11} {f(r.get('rms_deviation'), '.3e'):>11} "
      f"{'yes' if r.get('met') else 'no':>4}")
EOF
      else
        echo "scanflow fit at $n points, tolerance $tol failed:" >&2; tail -n 5 "$TMP/fit_$tag.log" >&2
      fi
    fi
    if [ "$PEERS" != 0 ] && [[ " $PEER_SIZES " == *" $n "* ]]; then
      scan=()
      [ "$HAVE_FIT" = 0 ] || scan=(--scanflow "$BIN" --threads "$THREADS")
      python3 scripts/spline_peers.py "$in" --tolerance "$tol" --timeout "$PEER_TIMEOUT" --grid "$GRIDS" \
        --out "$TMP/peers_$tag" "${scan[@]}" > "$TMP/peers_$tag.txt"
      sed '$d' "$TMP/peers_$tag.txt" | sed "s/^/  [$n, $tol] /"
      tail -n 1 "$TMP/peers_$tag.txt" >> "$TMP/peers.jsonl"
    fi
  done
done
echo
echo "fairness: same points, same machine. scanflow runs from the PLY file (reading, fitting,"
echo "measuring every point and writing the IGES included) with --threads $THREADS; the peers are"
echo "timed on arrays in memory (reading and measuring excluded), one thread each (FITPACK,"
echo "OpenCascade's approximation). OpenCascade needs gridded heights: its time includes the"
echo "griddata resampling, and its deviation includes what the grid loses. Peer deviations are"
echo "vertical residuals, scanflow's are distances to the surface (never larger). Control points:"
echo "scanflow's exported tensor surfaces (ctrl_pts) and its hierarchy (hier_pts)."
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?)"
[ "$PEERS" = 0 ] || echo "peer JSON lines: $TMP/peers.jsonl"
