#!/usr/bin/env bash
# Spectral point filtering (issue 14): scanflow filter against CGAL's jet and bilateral smoothing
# and a scipy plane projection, on the same points, same machine, same run.
#
# What it measures: N samples (default 1M) of sphere, torus and bumpy (scanflow synth) at
# --noise 0.002 and 0.005 (Gaussian, per coordinate, relative to the diagonal). Timed:
#   scanflow filter IN.ply -o OUT.ply --wiener                 (Wiener filter, SNR estimated)
#   scanflow filter IN.ply -o OUT.ply --lowpass gauss:F        for F in $LOWPASS
#     with --threads THREADS --progress none; skipped, with a note, when the binary has no
#     `filter` command yet
#   scripts/spectral_peers.py: CGAL jet_smooth_point_set (k sweep), bilateral_smooth_point_set
#     (k and sharpness-angle sweep, 3 iterations, PCA normals), scipy plane projection
# Every output is measured by `scanflow check OUT.ply --truth T --json` (every point's distance
# to the exact surface): rms_rel (RMS over the diagonal; the input itself reads back its noise
# level) and relief_scale (bumpy only: 1 the relief kept, < 1 flattened). The table gives, per
# row, rms_rel / the best peer's rms_rel and points/s / the fastest peer's points/s on the
# same points (lower rms ratio is better, higher speed ratio is better).
#
# usage: scripts/bench_spectral.sh            N=1000000 by default; N=200000 for a quick run
#   THREADS=2   SHAPES="sphere torus bumpy"   NOISES="0.002 0.005"   LOWPASS="0.1 0.15 0.2 0.3 0.45"
#   PEER_ARGS="..."  extra arguments for spectral_peers.py (e.g. --jet-k 24,48 --peers jet)
#   PEERS=0        scanflow rows only
#   BUILD=0        use the existing target/release/scanflow (default: cargo build --release first)
#   SCANFLOW=PATH  binary to measure (implies BUILD=0)
#   KEEP=DIR       keep the points, outputs and logs in DIR
set -euo pipefail
cd "$(dirname "$0")/.."
export PYTHONDONTWRITEBYTECODE=1   # no __pycache__ in scripts/
N=${N:-1000000}
[[ $N =~ ^[0-9]+$ ]] || { echo "N must be a number of points, not '$N'" >&2; exit 2; }
THREADS=${THREADS:-2}
SHAPES=${SHAPES:-sphere torus bumpy}
NOISES=${NOISES:-0.002 0.005}
LOWPASS=${LOWPASS:-0.1 0.15 0.2 0.3 0.45}
PEERS=${PEERS:-1}

# --- Python side: CGAL's bindings, scipy, numpy
if [ "$PEERS" != 0 ]; then
  python3 -c 'import CGAL.CGAL_Point_set_processing_3, scipy.spatial, numpy' 2>/dev/null ||
    python3 -m pip install --quiet --disable-pip-version-check cgal scipy numpy || {
      echo "pip could not install cgal scipy numpy (no index reachable? Python $(python3 -V 2>&1))" >&2; exit 1; }
  python3 -c 'import CGAL.CGAL_Point_set_processing_3, scipy.spatial' || { echo "CGAL or scipy does not import" >&2; exit 1; }
fi

# --- scanflow
if [ -n "${SCANFLOW:-}" ]; then BIN=$SCANFLOW
else
  BIN=$PWD/target/release/scanflow
  [ "${BUILD:-1}" = 0 ] || cargo build --release --quiet
fi
[ -x "$BIN" ] || { echo "no scanflow binary at $BIN" >&2; exit 1; }
HAVE_FILTER=1
"$BIN" filter --help > /dev/null 2>&1 || HAVE_FILTER=0

if [ -n "${KEEP:-}" ]; then TMP=$KEEP; mkdir -p "$TMP"
else TMP=$(mktemp -d -t scanflow-spectral-XXXX); trap 'rm -rf "$TMP"' EXIT; fi
ROWS=$TMP/rows.jsonl
: > "$ROWS"

echo "$N points; shapes: $SHAPES; noise: $NOISES; $THREADS threads, $(nproc) cores; scratch $TMP"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?) (a busy machine slows every side)"
[ "$HAVE_FILTER" = 1 ] || echo "note: $BIN has no 'filter' command yet: scanflow rows skipped, peers only"

# row SHAPE NOISE METHOD SETTING SECONDS CPU_SECONDS CHECK_JSON: one JSON line into $ROWS
row() {
  python3 - "$@" >> "$ROWS" <<'EOF'
import json, sys
shape, noise, method, setting, secs, cpu, rep = sys.argv[1:8]
rep = json.loads(rep) if rep else {}
secs = float(secs)
print(json.dumps({"shape": shape, "noise": float(noise), "method": method, "setting": setting,
                  "seconds": secs, "cpu_seconds": float(cpu) if cpu != "-" else None,
                  "points_per_s": rep.get("points", 0) / secs if secs > 0 else None,
                  "rms_rel": rep.get("rms_rel"), "relief_scale": rep.get("relief_scale")}))
EOF
}

# timed OUT_TIME CMD...: runs CMD, writes "wall_s cpu_s" (cpu: user + sys, "-" when unknown)
timed() {
  local out=$1 t0 t1 rc=0; shift
  if [ -x /usr/bin/time ]; then
    /usr/bin/time -f "%e %U %S" -o "$out.raw" "$@" || rc=$?
    awk '{printf "%s %.2f\n", $1, $2 + $3}' "$out.raw" > "$out"
  else
    t0=$(date +%s.%N); "$@" || rc=$?; t1=$(date +%s.%N)
    echo "$(echo "$t1 - $t0" | bc -l) -" > "$out"
  fi
  return "$rc"
}

for shape in $SHAPES; do
  for noise in $NOISES; do
    in=$TMP/${shape}_$noise.ply truth=$TMP/${shape}_$noise.truth.json
    [ -f "$in" ] || "$BIN" synth "$shape" --points "$N" --noise "$noise" -o "$in" --progress none > /dev/null
    cat "$in" > /dev/null   # warm page cache
    row "$shape" "$noise" input - 0 - "$("$BIN" check "$in" --truth "$truth" --json)"
    if [ "$HAVE_FILTER" = 1 ]; then
      settings=("--wiener")
      for f in $LOWPASS; do settings+=("--lowpass gauss:$f"); done
      for s in "${settings[@]}"; do
        out=$TMP/${shape}_${noise}_$(echo "$s" | tr -c 'a-z0-9.\n' '_').ply
        # shellcheck disable=SC2086  # $s is an option and its value
        if timed "$out.time" "$BIN" filter "$in" -o "$out" $s --threads "$THREADS" --progress none 2> "$out.log"; then
          row "$shape" "$noise" scanflow "${s#--}" "$(cut -d' ' -f1 "$out.time")" "$(cut -d' ' -f2 "$out.time")" \
            "$("$BIN" check "$out" --truth "$truth" --json)"
        else
          echo "scanflow filter $s on $shape $noise failed:" >&2; tail -n 5 "$out.log" >&2
        fi
      done
    fi
    if [ "$PEERS" != 0 ]; then
      # shellcheck disable=SC2086  # PEER_ARGS is a list of arguments
      python3 scripts/spectral_peers.py "$in" "$truth" --scanflow "$BIN" --threads "$THREADS" \
        --out "$TMP/peers" ${PEER_ARGS:-} > "$TMP/peers_${shape}_$noise.jsonl"
      python3 - "$shape" "$noise" "$TMP/peers_${shape}_$noise.jsonl" >> "$ROWS" <<'EOF'
import json, sys
shape, noise, path = sys.argv[1:4]
for line in open(path):
    r = json.loads(line)
    short = {"sharpness_angle": "angle", "iterations": "it"}
    setting = ",".join(f"{short.get(k, k)}={v:g}" if isinstance(v, float) else f"{short.get(k, k)}={v}"
                       for k, v in r["params"].items() if not (k == "normals" and v == "pca"))
    print(json.dumps({"shape": shape, "noise": float(noise), "method": r["peer"], "setting": setting,
                      "seconds": r["seconds"], "cpu_seconds": r.get("cpu_seconds"),
                      "points_per_s": r["points_per_s"],
                      "rms_rel": r["rms_rel"], "relief_scale": r["relief_scale"]}))
EOF
    fi
  done
done

echo
python3 - "$ROWS" <<'EOF'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
peer = lambda r: r["method"] not in ("scanflow", "input")
fmt = "{:<7} {:>6} {:<15} {:<22} {:>8} {:>7} {:>9} {:>10} {:>7} {:>9} {:>10}"
print(fmt.format("shape", "noise", "method", "setting", "seconds", "cpu_s", "points/s", "rms_rel",
                 "relief", "rms/best", "speed/best"))
f = lambda v, p: "-" if v is None else format(v, p)
for key in dict.fromkeys((r["shape"], r["noise"]) for r in rows):
    group = [r for r in rows if (r["shape"], r["noise"]) == key]
    peers = [r for r in group if peer(r) and r["rms_rel"] is not None]
    best_rms = min((r["rms_rel"] for r in peers), default=None)
    best_speed = max((r["points_per_s"] for r in peers if r["points_per_s"]), default=None)
    for r in group:
        rr = r["rms_rel"] / best_rms if best_rms and r["rms_rel"] is not None else None
        sr = r["points_per_s"] / best_speed if best_speed and r["points_per_s"] else None
        print(fmt.format(r["shape"], r["noise"], r["method"], r["setting"][:22],
                         f(r["seconds"] or None, ".2f"), f(r.get("cpu_seconds"), ".2f"),
                         f(r["points_per_s"], ".3g"),
                         f(r["rms_rel"], ".3e"), f(r["relief_scale"], ".3f"),
                         f(rr, ".2f"), f(sr, ".2f")))
EOF
echo
echo "fairness: same points, same machine; scanflow runs out of core with --threads $THREADS (its time"
echo "includes reading, its store and writing OUT.ply); the peers are timed in memory, files excluded."
echo "CGAL's Python bindings run single-threaded here; scipy's k-NN uses $THREADS workers. Bilateral"
echo "smoothing gets PCA normals (k = 24, scipy), their time included. 'input' is the noisy input"
echo "itself (its rms_rel reads back the noise level). Ratios are against the best peer on the same"
echo "points: rms/best < 1 is more accurate, speed/best > 1 faster (wall clock; cpu_s is the CPU"
echo "time, user + sys, which a busy machine inflates less)."
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?)"
