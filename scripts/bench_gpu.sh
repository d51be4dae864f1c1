#!/usr/bin/env bash
# The GPU path end to end: `reconstruct` with the leaf solves and the tiles on the GPU
# (--gpu-solve on --gpu on) against the CPU alone (the defaults), same points, same machine,
# same run: each stage's time and the ratio CPU/GPU, the device thread's batches, and the
# distance between the two meshes (the GPU solve sums in float32: within rounding, not the
# same bytes). Meant for a machine with a real GPU (issue: the H100/H200 machine, 16 cores).
#
#   scripts/bench_gpu.sh                          # 1M-point bumpy sphere, depths 10 and 11
#   BIG=100000000 scripts/bench_gpu.sh            # and a 100M-point sphere at depth 11
#   BIN=.bin/scanflow DEPTHS="11" scripts/bench_gpu.sh   # a prebuilt binary (no cargo there)
#
# Vulkan needs the loader (libvulkan1) and a driver. Where the NVIDIA driver's ICD file is
# under /usr/local/nvidia (containers), it is used.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${BIN:-}" ]; then
  cargo build --release --quiet
  BIN=$PWD/target/release/scanflow
fi
ICD=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$ICD" ] && export VK_DRIVER_FILES=$ICD
THREADS=${THREADS:-0} MEM=${MEM:-32G} DEPTHS=${DEPTHS:-"10 11"} POINTS=${POINTS:-1000000}
DIR=${DIR:-$(mktemp -d -t scanflow-gpu-XXXX)}
mkdir -p "$DIR"

run() {  # label input depth [options]: one reconstruct, its stage times in $DIR/label.stages
  local label=$1 input=$2 depth=$3; shift 3
  /usr/bin/time -f "%e %M" -o "$DIR/$label.time" "$BIN" reconstruct "$input" -o "$DIR/$label.ply" \
    --depth "$depth" --mem "$MEM" --threads "$THREADS" --progress json "$@" > "$DIR/$label.log" 2>&1 || {
    echo "$label failed:"; tail -5 "$DIR/$label.log"; exit 1; }
  grep -i "GPU" "$DIR/$label.log" | grep -v '^{\|^reconstructed' | sed 's/^/    /' || true
}

compare() {  # input depth label: CPU and GPU runs, stage by stage
  local input=$1 depth=$2 label=$3
  run "${label}_cpu" "$input" "$depth"
  run "${label}_gpu" "$input" "$depth" --gpu on --gpu-solve on
  python3 - "$DIR" "$label" "$BIN" <<'PY'
import json, subprocess, sys
d, label, bin_ = sys.argv[1:4]
def stages(run):
    out = {}
    for l in open(f"{d}/{label}_{run}.log"):
        if l.startswith("{") and '"state":"done"' in l:
            j = json.loads(l)
            out[j["stage"]] = j["elapsed_s"]
    t, m = open(f"{d}/{label}_{run}.time").read().split()
    out["total"] = float(t)
    return out, int(m) / 1024
(c, cm), (g, gm) = stages("cpu"), stages("gpu")
print(f"{label}: CPU {c['total']:.1f} s {cm:.0f} MiB, GPU {g['total']:.1f} s {gm:.0f} MiB")
for s in c:
    if s in g and g[s] > 0:
        print(f"    {s:>8}: CPU {c[s]:8.2f} s  GPU {g[s]:8.2f} s  CPU/GPU {c[s] / g[s]:5.2f}")
r = json.loads(subprocess.check_output([bin_, "check", f"{d}/{label}_gpu.ply", "--reference",
                                        f"{d}/{label}_cpu.ply", "--samples", "100000", "--json"]))
rel = r["comparison"]["relative"]
print(f"    GPU mesh to CPU mesh, relative to the diagonal: max "
      f"{max(rel['to_reference']['max'], rel['from_reference']['max']):.2e}, mean "
      f"{rel['to_reference']['mean']:.2e}")
PY
  rm -f "$DIR/${label}"_*.ply
}

"$BIN" synth bumpy --points "$POINTS" --noise 0.0005 -o "$DIR/bumpy.ply" --progress none > /dev/null
for depth in $DEPTHS; do
  compare "$DIR/bumpy.ply" "$depth" "bumpy_${POINTS}_d$depth"
done
if [ -n "${BIG:-}" ]; then
  "$BIN" synth sphere --points "$BIG" --noise 0.0005 -o "$DIR/big.ply" --progress none > /dev/null
  "$BIN" ingest "$DIR/big.ply" -o "$DIR/big.store" --threads "$THREADS" --mem "$MEM" --progress none > /dev/null
  rm -f "$DIR/big.ply"
  compare "$DIR/big.store" 11 "sphere_${BIG}_d11"
fi
