#!/usr/bin/env bash
# scanflow reconstruct against PoissonRecon (screened Poisson as shipped in pymeshlab) in
# the same run, on the same points: wall time, peak memory, two-sided distances to the
# analytic truth, printed as ratios (scanflow / peer; below 1 is better for all three).
#
#   scripts/bench_reconstruct.sh                       # 1M points, bumpy and torus, depths 9 10
#   N=200000 DEPTHS="8" SHAPES=sphere scripts/bench_reconstruct.sh
#   BIG=1 scripts/bench_reconstruct.sh                 # also 100M-point sphere, depth 11, --mem 4G
#
# Fairness: both get the same oriented points (no noise removal), the same depth (cells per
# edge of a cube 1.1x the bounding box), THREADS threads (default 2), a warm page cache.
# PoissonRecon is screened (point weight 4, MeshLab's default); scanflow solves the
# unscreened Poisson equation, adaptively, out of core. Distances come from `scanflow check`
# for both meshes, with the same seeds.
set -euo pipefail
cd "$(dirname "$0")/.."
N=${N:-1000000}
DEPTHS=${DEPTHS:-"9 10"}
SHAPES=${SHAPES:-"bumpy torus"}
THREADS=${THREADS:-2}
NOISE=${NOISE:-0.001}
DIR=${DIR:-$(mktemp -d -t scanflow-recon-bench-XXXX)}
mkdir -p "$DIR"
cargo build --release --quiet
BIN=$PWD/target/release/scanflow
python3 -c "import pymeshlab" 2>/dev/null || python3 -m pip install --quiet pymeshlab

# run LABEL CMD...: wall seconds and peak RSS (KiB) from GNU time into $DIR/LABEL.time
run() {
  local label=$1; shift
  /usr/bin/time -f "%e %M" -o "$DIR/$label.time" "$@" > "$DIR/$label.log" 2>&1 || {
    echo "$label failed:"; tail -5 "$DIR/$label.log"; exit 1; }
}
dist() { "$BIN" check "$1" --truth "$2" --samples 200000 --json; }

printf '%-7s %5s  %9s %9s %6s  %9s %9s %6s  %11s %11s %6s  %11s %11s %6s\n' \
  shape depth "ours s" "peer s" ratio "ours MiB" "peer MiB" ratio "ours mean" "peer mean" ratio "ours max" "peer max" ratio
for shape in $SHAPES; do
  PLY=$DIR/$shape.ply
  [ -f "$PLY" ] || "$BIN" synth "$shape" --points "$N" --noise "$NOISE" -o "$PLY" --progress none > /dev/null
  TRUTH=$DIR/$shape.truth.json
  for depth in $DEPTHS; do
    cat "$PLY" > /dev/null
    run "ours_${shape}_$depth" "$BIN" reconstruct "$PLY" -o "$DIR/ours_${shape}_$depth.ply" --depth "$depth" --threads "$THREADS" --progress none
    run "peer_${shape}_$depth" python3 scripts/poisson_peer.py "$PLY" "$DIR/peer_${shape}_$depth.ply" "$depth" "$THREADS"
    dist "$DIR/ours_${shape}_$depth.ply" "$TRUTH" > "$DIR/ours_${shape}_$depth.json"
    dist "$DIR/peer_${shape}_$depth.ply" "$TRUTH" > "$DIR/peer_${shape}_$depth.json"
    python3 - "$DIR" "$shape" "$depth" <<'PY'
import json, sys
d, shape, depth = sys.argv[1], sys.argv[2], sys.argv[3]
def load(who):
    t, m = open(f"{d}/{who}_{shape}_{depth}.time").read().split()
    j = json.load(open(f"{d}/{who}_{shape}_{depth}.json"))
    c = j["comparison"]["absolute"]
    # two-sided: the mean of both directions, the larger max
    mean = 0.5 * (c["to_reference"]["mean"] + c["from_reference"]["mean"])
    mx = max(c["to_reference"]["max"], c["from_reference"]["max"])
    return float(t), int(m) / 1024, mean, mx, j["check"]
o, p = load("ours"), load("peer")
print(f"{shape:7s} {depth:>5s}  {o[0]:9.1f} {p[0]:9.1f} {o[0]/p[0]:6.2f}  {o[1]:9.0f} {p[1]:9.0f} {o[1]/p[1]:6.2f}  {o[2]:11.3e} {p[2]:11.3e} {o[2]/p[2]:6.2f}  {o[3]:11.3e} {p[3]:11.3e} {o[3]/p[3]:6.2f}")
for who, r in (("ours", o), ("peer", p)):
    c = r[4]
    print(f"        {who}: {c['vertices']} vertices, {c['triangles']} triangles, {c['components']} components, watertight {c['watertight']}")
PY
  done
done
echo "targets: time ratio <= 0.5, memory ratio <= 0.25, mean distance ratio <= 1.0"
if [ -n "${BIG:-}" ]; then
  PLY=$DIR/big.ply
  [ -f "$PLY" ] || "$BIN" synth sphere --points 100000000 --noise 0.0005 -o "$PLY" --progress none > /dev/null
  run big "$BIN" reconstruct "$PLY" -o "$DIR/big_mesh.ply" --depth 11 --mem 4G --threads "$THREADS" --progress json
  read -r t m < "$DIR/big.time"
  echo "100M-point sphere, depth 11, --mem 4G: $t s, peak $((m / 1024)) MiB"
  tail -1 "$DIR/big.log"
fi
