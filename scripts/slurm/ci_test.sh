#!/usr/bin/env bash
# The cluster test: a real one-node SLURM cluster on localhost (local_cluster.sh) runs a
# reconstruction as submit.sh submits it (an ingest array of 3 tasks, an array of 3 shards,
# merge, chained by afterok), and the store and the merged mesh must be those of one
# process. Then the same run
# again with one array task requeued while it runs (scontrol requeue: SLURM kills it and
# starts it again), which must still give the same bytes.
#
# usage: ci_test.sh SCANFLOW_BINARY. Exit 0: passed; 77: SLURM cannot be had here (the reason
# on stderr); anything else: failed.
set -euo pipefail
bin=$(cd "$(dirname "$1")" && pwd)/$(basename "$1")
here=$(cd "$(dirname "$0")" && pwd)
"$here/local_cluster.sh" start || exit $?
tmp=$(mktemp -d /tmp/scanflow-slurm.XXXXXX)
cleanup() { scancel --user="$(id -un)" 2>/dev/null || true; "$here/local_cluster.sh" stop; rm -rf "$tmp"; }
trap cleanup EXIT
cd "$tmp"
opts="--depth 9"
mem=256M
"$bin" synth torus --points 300000 --noise 0.0005 -o torus.ply --progress none >/dev/null
# The reference: one process, same store options, options and budget.
"$bin" ingest torus.ply -o ref.store --progress none >/dev/null
"$bin" reconstruct ref.store -o ref.ply $opts --mem $mem --progress none >/dev/null

# The states of job $1's tasks, one per line (none while SLURM does not answer).
states() { scontrol show job "$1" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | cut -d= -f2 || true; }
# Wait until every task of job $1 has ended; fail after $2 seconds.
wait_job() {
  local s
  for _ in $(seq $(($2 * 2))); do
    s=$(states "$1")
    if [ -n "$s" ] && ! grep -qvE '^(COMPLETED|FAILED|CANCELLED|TIMEOUT|NODE_FAIL|OUT_OF_MEMORY|DEADLINE)$' <<<"$s"; then
      return 0
    fi
    sleep 0.5
  done
  echo "job $1 not ended after $2 s:" >&2; squeue >&2; return 1
}
# The last field of submit.sh's line $2 in the output $1: a job id.
job_of() { grep "^$2:" <<<"$1" | grep -o '[0-9][0-9]*' | head -1; }
check_same() {
  if [ ! -f "$1" ]; then
    echo "FAIL: $1 not written; logs:" >&2; tail -n 5 "$tmp"/scratch/logs/* >&2; exit 1
  fi
  cmp "$1" ref.ply || { echo "FAIL: $1 differs from the single-process mesh" >&2; exit 1; }
}

# 1. Ingest, 3 shards, merge.
out=$("$here/submit.sh" -n 3 -d scratch -o sharded.ply -m $mem -c 1 -b "$bin" -r "$opts" torus.ply)
echo "$out"
wait_job "$(job_of "$out" merge)" 300
check_same sharded.ply
[ ! -e scratch/ingest-work ] || { echo "FAIL: the ingest left its work directory" >&2; exit 1; }
# The split store holds the cells (keys, counts, bounds) of one process's store.
cells() { python3 -c "import json,sys; m=json.load(open(sys.argv[1])); print(m['point_count'], [(c['key'], c['count'], c['bounds']) for c in m['cells']])" "$1"; }
[ "$(cells scratch/store/manifest.json)" = "$(cells ref.store/manifest.json)" ] || { echo "FAIL: the split ingest's cells differ from one process's" >&2; exit 1; }
[ ! -e scratch/work ] || { echo "FAIL: merge left the work directory:" >&2; ls -laR scratch/work | head -20 >&2; cat scratch/logs/merge-* >&2; exit 1; }
echo "slurm: 3 ingest tasks and 3 shards merged into the single-process bytes"

# 2. The store is reused; shard 1 is requeued while it runs.
out=$("$here/submit.sh" -n 3 -d scratch -o requeued.ply -m $mem -c 1 -b "$bin" -r "$opts")
echo "$out"
array=$(job_of "$out" reconstruct)
requeued=
for _ in $(seq 1200); do
  state=$(states "${array}_1")
  if [ "$state" = RUNNING ]; then
    sleep 1
    scontrol requeue "${array}_1" && requeued=yes
    break
  fi
  case $state in COMPLETED|FAILED|CANCELLED) break ;; esac
  sleep 0.1
done
[ -n "$requeued" ] || { echo "FAIL: shard 1 was never seen running to requeue it (state: $state)" >&2; tail -n 3 scratch/logs/* >&2; exit 1; }
restarts=$(scontrol show job "${array}_1" 2>/dev/null | grep -o "Restarts=[0-9]*" | head -1 || true)
echo "slurm: requeued shard 1 ($restarts)"
wait_job "$(job_of "$out" merge)" 600
check_same requeued.ply
echo "slurm: with shard 1 requeued mid-run, the same bytes"
