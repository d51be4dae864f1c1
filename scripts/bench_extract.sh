#!/usr/bin/env bash
# Marching cubes per tile: CPU (one core and all cores) against the GPU path (wgpu), in cells
# per second, the GPU split into upload, kernels, download and host work, printed as ratios.
# The GPU mesh is checked identical to the CPU mesh first. See benches/extract.rs for what is
# compared and why it is fair (it favours the CPU).
#
#   scripts/bench_extract.sh                     # tiles of 256³ and 512³ cells, any GPU
#   SIZES="32 64" REPS=2 scripts/bench_extract.sh  # small, e.g. on lavapipe
#   GPU=auto scripts/bench_extract.sh            # a discrete or integrated GPU only
set -euo pipefail
cd "$(dirname "$0")/.."
SIZES=${SIZES:-"256 512"} REPS=${REPS:-3} GPU=${GPU:-on} cargo bench --bench extract
