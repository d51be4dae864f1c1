#!/usr/bin/env bash
# Scale: one big run per line, each with its time, peak resident memory and two-sided distance
# to the exact surface, and the per-stage rates a plan for a billion points is made from.
#
#   scripts/bench_scale.sh                         # a LiDAR terrain at depths 10 and 11; a
#                                                  # 10M-point sphere, depth 10, --mem 1G, 128M
#   BIG=1 scripts/bench_scale.sh                   # also 100M points, depth 11 and 12, --mem 4G
#   SHARDS=3 scripts/bench_scale.sh                # also the 10M run as 3 concurrent shards + merge
#
# The sphere lines: the same points (a synth sphere, noise 0.0005 of the diagonal); every line
# THREADS threads (default: all cores), a warm page cache. The rates come from the JSON progress lines (the
# `done` line of each stage: items and seconds).
set -euo pipefail
cd "$(dirname "$0")/.."
THREADS=${THREADS:-0}
DIR=${DIR:-$(mktemp -d -t scanflow-scale-XXXX)}
mkdir -p "$DIR"
cargo build --release --quiet
BIN=$PWD/target/release/scanflow

# run LABEL CMD...: wall seconds and peak RSS (KiB) from GNU time into $DIR/LABEL.time
run() {
  local label=$1; shift
  /usr/bin/time -f "%e %M" -o "$DIR/$label.time" "$@" > "$DIR/$label.log" 2>&1 || {
    echo "$label failed:"; tail -5 "$DIR/$label.log"; exit 1; }
}

# line LABEL POINTS MESH TRUTH: time, peak, distance, and the stages' rates
line() {
  python3 - "$DIR" "$1" "$2" "$3" "$4" "$BIN" <<'PY'
import json, subprocess, sys
d, label, points, mesh, truth, bin_ = sys.argv[1:7]
t, m = open(f"{d}/{label}.time").read().split()
rates = []
for l in open(f"{d}/{label}.log"):
    if l.startswith("{"):
        j = json.loads(l)
        if j.get("state") == "done" and j.get("elapsed_s", 0) > 0:
            rates.append(f"{j['stage']} {j['done']} {j['unit']} in {j['elapsed_s']:.1f} s ({j['done'] / j['elapsed_s']:,.0f}/s)")
dist = ""
if mesh != "-":
    c = json.loads(subprocess.check_output([bin_, "check", mesh, "--truth", truth, "--samples", "200000", "--json"]))
    a = c["comparison"]["absolute"]
    mean = 0.5 * (a["to_reference"]["mean"] + a["from_reference"]["mean"])
    mx = max(a["to_reference"]["max"], a["from_reference"]["max"])
    dist = f", mean distance {mean:.3e}, max {mx:.3e}"
print(f"{label}: {int(points):,} points, {float(t):.1f} s, peak {int(m) / 1024:.0f} MiB{dist}")
for r in rates:
    print(f"    {r}")
PY
}

sphere() {  # sphere N: the PLY and its store, made once
  local n=$1 ply=$DIR/sphere_$1.ply
  [ -f "$ply" ] || "$BIN" synth sphere --points "$n" --noise 0.0005 -o "$ply" --progress none > /dev/null
  if [ ! -d "$DIR/sphere_$n.store" ]; then
    cat "$ply" > /dev/null
    run "ingest_$n" "$BIN" ingest "$ply" -o "$DIR/sphere_$n.store" --threads "$THREADS" --mem 4G --progress json
    line "ingest_$n" "$n" - -
  fi
}

recon() {  # recon N DEPTH MEM
  local n=$1 depth=$2 mem=$3 label="recon_$1_d$2_$3"
  run "$label" "$BIN" reconstruct "$DIR/sphere_$n.store" -o "$DIR/$label.ply" --depth "$depth" \
    --mem "$mem" --threads "$THREADS" --progress json
  line "$label" "$n" "$DIR/$label.ply" "$DIR/sphere_$n.truth.json"
  rm -f "$DIR/$label.ply"
}

# terrain DEPTH [--trim]: the Autzen LiDAR tile (real, 110K points, normals estimated), closed
# or trimmed. Closed, the surface's underside lies tens of voxels below the ground, far from
# every point: what the vertex fit's nearest-point search must stay fast on (at depth 10 the
# tile stage ran at 2 tiles a second before the search took a k-d tree for such vertices).
terrain() {
  local depth=$1 trim=${2:-} label="autzen_d$1${2:+_trim}"
  run "$label" "$BIN" reconstruct "$LAS" -o "$DIR/$label.ply" --depth "$depth" $trim --mem 4G \
    --threads "$THREADS" --progress json
  line "$label" "$(python3 -c 'import json, sys
print(next(j["done"] for j in map(json.loads, filter(lambda l: l.startswith("{"), open(sys.argv[1])))
           if j.get("stage") == "count" and j.get("state") == "done"))' "$DIR/$label.log")" - -
  rm -f "$DIR/$label.ply"
}

LAS=${LAS:-../shared/data/lidar/autzen_trim.las}
if [ -f "$LAS" ]; then
  terrain 10
  terrain 10 --trim
  terrain 11
else
  echo "terrain: $LAS is absent, skipped"
fi
sphere 10000000
recon 10000000 10 1G
recon 10000000 10 128M
if [ -n "${SHARDS:-}" ]; then
  out=$DIR/shards.ply work=$DIR/shards.work
  start=$(date +%s.%N)
  for i in $(seq 0 $((SHARDS - 1))); do
    "$BIN" reconstruct "$DIR/sphere_10000000.store" --shard "$i/$SHARDS" --work-dir "$work" -o "$out" \
      --depth 10 --mem 1G --threads 1 --progress none > "$DIR/shard_$i.log" 2>&1 &
  done
  wait
  "$BIN" merge "$work" -o "$out" --progress none
  echo "$SHARDS shards + merge: $(echo "$(date +%s.%N) - $start" | bc) s"
  "$BIN" reconstruct "$DIR/sphere_10000000.store" -o "$DIR/single.ply" --depth 10 --mem 1G --progress none > /dev/null
  cmp "$out" "$DIR/single.ply" && echo "sharded = single: identical bytes"
fi
if [ -n "${BIG:-}" ]; then
  sphere 100000000
  recon 100000000 11 4G
  # The issue's target on the 2-core VM this was planned on: 100M points at depth 11 in 4
  # minutes (measured there: 195 s from the store).
  t=$(cut -d' ' -f1 "$DIR/recon_100000000_d11_4G.time")
  echo "    target 240 s on 2 cores: $(python3 -c "print('met' if $t <= 240 else 'missed')") ($t s on $(nproc) cores)"
  recon 100000000 12 4G
fi
