#!/usr/bin/env bash
# Submit a whole scanflow reconstruction to SLURM as three chained jobs:
#
#   ingest (array of G tasks) ──afterok──▶ reconstruct (array of N shards) ──afterok──▶ merge (1 task)
#
# usage: submit.sh -n SHARDS -d SCRATCH -o OUT.ply [-g INGEST_TASKS] [-m MEM] [-c CPUS]
#                  [-b SCANFLOW] [-r "RECONSTRUCT OPTIONS"] [-i "INGEST OPTIONS"]
#                  [-s "SBATCH OPTIONS"] INPUT...
#
#   -n  shards: array tasks of the reconstruction (each runs on its own node or cores)
#   -g  array tasks of the ingest (default: SHARDS); 1 ingests in one task
#   -d  a directory on the file system every node shares (NFS, Lustre, GPFS): the store goes
#       to SCRATCH/store, the ingest tasks' work directory to SCRATCH/ingest-work, the
#       shards' to SCRATCH/work, logs to SCRATCH/logs
#   -o  the mesh to write (binary PLY), on the shared file system
#   -m  scanflow's memory budget per task (default 4G); SLURM is asked for it plus 512 MiB
#   -c  CPUs per task (default 8)
#   -b  the scanflow binary, as the nodes see it (default: the scanflow on PATH here)
#   -r  more reconstruct options, the same for every shard (e.g. "--depth 11 --trim")
#   -i  more ingest options (e.g. "--normals estimate")
#   -s  more sbatch options for all three jobs (e.g. "--partition=long --account=geo")
#
# Prints the three job ids. A store already complete at SCRATCH/store is reused (no ingest
# job). To re-run a failed or cancelled task of either array, resubmit its index alone with
# the same environment: sbatch --array=K ... ingest.sbatch or reconstruct.sbatch (it skips
# the work already done).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
shards= ingest_tasks= scratch= out= mem=4G cpus=8 bin=$(command -v scanflow || true)
recon_opts= ingest_opts= sbatch_opts=
while getopts "n:g:d:o:m:c:b:r:i:s:" opt; do
  case $opt in
    n) shards=$OPTARG ;; g) ingest_tasks=$OPTARG ;; d) scratch=$OPTARG ;; o) out=$OPTARG ;; m) mem=$OPTARG ;;
    c) cpus=$OPTARG ;; b) bin=$OPTARG ;; r) recon_opts=$OPTARG ;; i) ingest_opts=$OPTARG ;;
    s) sbatch_opts=$OPTARG ;;
    *) sed -n '2,28p' "$0" >&2; exit 2 ;;
  esac
done
shift $((OPTIND - 1))
die() { echo "submit.sh: $*" >&2; exit 2; }
[ -n "$shards" ] && [ "$shards" -ge 1 ] 2>/dev/null || die "-n SHARDS: a number of shards, 1 or more"
ingest_tasks=${ingest_tasks:-$shards}
[ "$ingest_tasks" -ge 1 ] 2>/dev/null || die "-g INGEST_TASKS: a number of tasks, 1 or more"
[ -n "$scratch" ] || die "-d SCRATCH: a directory on the shared file system"
[ -n "$out" ] || die "-o OUT.ply: the mesh to write"
[ -n "$bin" ] && [ -x "$bin" ] || die "-b SCANFLOW: no scanflow binary (not on PATH, or not executable)"
[ $# -ge 1 ] || [ -f "$scratch/store/manifest.json" ] || die "no INPUT point files"
# SLURM's --mem in MiB: scanflow's budget plus its margin and the process's own (512 MiB).
case $mem in
  *[Gg]) mib=$(( ${mem%[Gg]} * 1024 )) ;;
  *[Mm]) mib=${mem%[Mm]} ;;
  *) die "-m MEM: a size in M or G, e.g. 4G" ;;
esac
mkdir -p "$scratch/logs"
abs() { case $1 in /*) echo "$1" ;; *) echo "$PWD/$1" ;; esac; }
inputs=()
for f in "$@"; do inputs+=("$(abs "$f")"); done
export SCANFLOW=$(abs "$bin") SF_STORE=$(abs "$scratch/store") SF_WORK=$(abs "$scratch/work")
export SF_INGEST_WORK=$(abs "$scratch/ingest-work")
export SF_OUT=$(abs "$out") SF_MEM=$mem SF_INPUTS="${inputs[*]}"
export SF_RECON_OPTS=$recon_opts SF_INGEST_OPTS=$ingest_opts
read -r -a extra <<<"$sbatch_opts"
common=(--parsable --export=ALL --cpus-per-task="$cpus" --mem="$((mib + 512))M" "${extra[@]}")
dep=()
if [ ! -f "$SF_STORE/manifest.json" ]; then
  ingest=$(sbatch "${common[@]}" --array=0-$((ingest_tasks - 1)) \
    --output="$scratch/logs/ingest-%A_%a.txt" "$here/ingest.sbatch")
  dep=(--dependency=afterok:"$ingest")
  echo "ingest: array job $ingest ($ingest_tasks tasks)"
fi
array=$(sbatch "${common[@]}" "${dep[@]}" --array=0-$((shards - 1)) \
  --output="$scratch/logs/shard-%A_%a.txt" "$here/reconstruct.sbatch")
echo "reconstruct: array job $array ($shards shards)"
merge=$(sbatch "${common[@]}" --dependency=afterok:"$array" \
  --output="$scratch/logs/merge-%j.txt" "$here/merge.sbatch")
echo "merge: job $merge"
