#!/usr/bin/env bash
# Fine relief, with and without noise: scanflow reconstruct (the default, screened with 4
# lowered for noise beyond 0.85 voxel between close samples and to the relief's share where
# noise from 0.35 to 0.75 voxel outweighs it, or 8 for precise samples, its
# Gaussian's width from the measured precision narrowed by the noise's share of the quadrics'
# residual, with the vertex fit, which noise beyond a third of a voxel stops; the *.log
# summaries give the three noise figures; --point-weight auto, also raised for
# precise samples: the *.log files give the weight and the measured noise; unscreened,
# --point-weight 0; and the default with --no-fit) against PoissonRecon (screened, pymeshlab) and Open3D's Poisson on the same points, same
# depth, same run (scripts/poisson_peer.py). A sphere of radius 1 carries the relief
# 1 + a sin(k x) sin(k y) sin(k z) (`scanflow synth bumpy --amplitude a --frequency k`); its
# wavelength 2π/k is WAVES voxels at DEPTH (a voxel is 1.1 × the bounding box over 2^DEPTH,
# PoissonRecon's and scanflow's cube). Prints the mean and max two-sided distance to the exact surface, wall time
# and peak memory, and the ratios scanflow / peer (below 1: scanflow better).
#
#   scripts/bench_relief.sh                                  # 1M points, depth 9, a = 1%
#   N=200000 WAVES="18" AMPS="0.005 0.02" NOISES=0 scripts/bench_relief.sh
set -euo pipefail
cd "$(dirname "$0")/.."
N=${N:-1000000}
DEPTH=${DEPTH:-9}
WAVES=${WAVES:-"8 12 18 30"}
AMPS=${AMPS:-"0.01"}
NOISES=${NOISES:-"0 0.001"}
THREADS=${THREADS:-2}
DIR=${DIR:-$(mktemp -d -t scanflow-relief-bench-XXXX)}
mkdir -p "$DIR"
cargo build --release --quiet
BIN=$PWD/target/release/scanflow
python3 -c "import pymeshlab, numpy" 2>/dev/null || python3 -m pip install --quiet pymeshlab numpy
dist() {
  "$BIN" check "$1" --truth "$2" --samples 200000 --json | python3 -c '
import json, sys
c = json.load(sys.stdin)["comparison"]["absolute"]
print(0.5 * (c["to_reference"]["mean"] + c["from_reference"]["mean"]),
      max(c["to_reference"]["max"], c["from_reference"]["max"]))'
}
. scripts/peer_env.sh
if (need_open3d numpy) > /dev/null 2>&1; then O3D=1; else O3D=0; echo "open3d cannot be installed here: its column is left out"; fi
# run LABEL CMD...: wall seconds and peak RSS (MiB) of CMD, printed as "S MIB"
run() {
  local label=$1; shift
  /usr/bin/time -f "%e %M" -o "$DIR/$label.time" "$@" > "$DIR/$label.log" 2>&1 || {
    echo "$label failed:" >&2; tail -5 "$DIR/$label.log" >&2; exit 1; }
  awk '{printf "%s %.0f\n", $1, $2 / 1024}' "$DIR/$label.time"
}
printf '%5s %4s %5s | %9s %9s %9s %9s %9s %9s %5s %5s %5s | %9s %9s %9s %5s | %5s %5s %5s %5s | %4s %4s %4s\n' \
  amp wave noise "default" "auto" "unscreen" "no-fit" "PR" "O3D" "/PR" "/O3D" "auto/PR" "max" "PR max" "O3D max" "/PR" \
  "fit s" "α=0 s" "PR s" "O3D s" "MiB" "PR" "O3D"
for a in $AMPS; do
  for w in $WAVES; do
    k=$(python3 -c "import math; print(2 * math.pi / ($w * 1.1 * 2 * (1 + $a) / 2 ** $DEPTH))")
    for noise in $NOISES; do
      tag=a${a}_w${w}_n${noise}
      PLY=$DIR/$tag.ply
      [ -f "$PLY" ] || "$BIN" synth bumpy --points "$N" --amplitude "$a" --frequency "$k" \
        --noise "$noise" -o "$PLY" --progress none > /dev/null
      TRUTH=$DIR/$tag.truth.json
      cat "$PLY" > /dev/null
      read -r fs fmb < <(run "fit_$tag" "$BIN" reconstruct "$PLY" -o "$DIR/fit_$tag.ply" --depth "$DEPTH" --threads "$THREADS" --progress none)
      run "auto_$tag" "$BIN" reconstruct "$PLY" -o "$DIR/auto_$tag.ply" --depth "$DEPTH" --threads "$THREADS" --point-weight auto --progress none > /dev/null
      read -r us _ < <(run "unscr_$tag" "$BIN" reconstruct "$PLY" -o "$DIR/unscr_$tag.ply" --depth "$DEPTH" --threads "$THREADS" --point-weight 0 --progress none)
      run "nofit_$tag" "$BIN" reconstruct "$PLY" -o "$DIR/nofit_$tag.ply" --depth "$DEPTH" --threads "$THREADS" --no-fit --progress none > /dev/null
      read -r ps pmb < <(run "pr_$tag" python3 scripts/poisson_peer.py "$PLY" "$DIR/pr_$tag.ply" "$DEPTH" "$THREADS")
      read -r fm fx < <(dist "$DIR/fit_$tag.ply" "$TRUTH")
      read -r am _ < <(dist "$DIR/auto_$tag.ply" "$TRUTH")
      read -r nm nx < <(dist "$DIR/nofit_$tag.ply" "$TRUTH")
      read -r um ux < <(dist "$DIR/unscr_$tag.ply" "$TRUTH")
      read -r pm px < <(dist "$DIR/pr_$tag.ply" "$TRUTH")
      os=nan omb=nan om=nan ox=nan
      if [ "$O3D" = 1 ]; then
        read -r os omb < <(run "o3d_$tag" python3 scripts/poisson_peer.py --open3d "$PLY" "$DIR/o3d_$tag.ply" "$DEPTH" "$THREADS")
        read -r om ox < <(dist "$DIR/o3d_$tag.ply" "$TRUTH")
      fi
      python3 -c "
n = float('nan')
fm, am, um, nm, pm, om, fx, px, ox = $fm, $am, $um, $nm, $pm, $om, $fx, $px, $ox
fs, us, ps, os_, fmb, pmb, omb = $fs, $us, $ps, $os, $fmb, $pmb, $omb
print('%5s %4s %5s | %9.2e %9.2e %9.2e %9.2e %9.2e %9.2e %5.2f %5.2f %5.2f | %9.2e %9.2e %9.2e %5.2f | %5.1f %5.1f %5.1f %5.1f | %4.0f %4.0f %4.0f' % (
    '$a', '$w', '$noise', fm, am, um, nm, pm, om, fm / pm, fm / om, am / pm, fx, px, ox, fx / px, fs, us, ps, os_, fmb, pmb, omb))"
    done
  done
done
echo "mean two-sided distance to the exact surface (the default, --point-weight auto, unscreened,"
echo "the default with --no-fit, PoissonRecon, Open3D), ratios scanflow / peer (the default's,"
echo "then auto's); the default's max; wall seconds; peak MiB. Target: mean ratio <= 1 on every row, time"
echo "ratio <= 0.5 and memory ratio <= 0.25 (issue: screened solve, curvature fit)"
