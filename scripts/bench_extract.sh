#!/usr/bin/env bash
# Marching cubes per tile: CPU (one core and all cores) against the GPU path (wgpu), in cells
# per second, the GPU time split into upload, kernels, download and host work, printed as
# ratios. The GPU mesh is checked identical to the CPU mesh first. A second table does the same
# for blended tiles (the reconstruction's case): the field blended from leaf grids on the host
# and extracted, against the field built on the device (leaves sent, or already resident), with
# the bytes sent against the dense tile's. See benches/extract.rs for what is compared and why
# it is fair (it favours the CPU).
#
#   scripts/bench_extract.sh                       # tiles of 256³ and 512³ cells, any GPU
#   SIZES="32 64" REPS=2 scripts/bench_extract.sh  # small, e.g. on lavapipe
#   GPU=auto scripts/bench_extract.sh              # a discrete or integrated GPU only
#   NVIDIA_EGL_ICD=1 scripts/bench_extract.sh      # headless NVIDIA container, see below
#
# Vulkan needs the loader (libvulkan1) and a driver. In headless NVIDIA containers the
# installed ICD file often names libGLX_nvidia.so.0, which fails without an X server ("Could
# not get 'vkCreateInstance' via 'vk_icdGetInstanceProcAddr'"), so wgpu finds no adapter;
# NVIDIA_EGL_ICD=1 points the loader at libEGL_nvidia.so.0 instead.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -n "${NVIDIA_EGL_ICD:-}" ]; then
  ICD=$(mktemp -t nvidia-egl-icd-XXXX.json)
  printf '{"file_format_version":"1.0.1","ICD":{"library_path":"libEGL_nvidia.so.0","api_version":"1.3.0"}}\n' > "$ICD"
  export VK_ICD_FILENAMES=$ICD
fi
SIZES=${SIZES:-"256 512"} REPS=${REPS:-3} GPU=${GPU:-on} cargo bench --bench extract
