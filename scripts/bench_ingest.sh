#!/usr/bin/env bash
# Ingest benchmark against the physical limit of reading the same file.
#
# Makes an N-point binary PLY with `scanflow synth` (default 100M points, 2.4 GB), then in the
# same run times `cat FILE > /dev/null` (the read floor: page cache as warm as for ingest), the
# disk's direct write rate (`dd oflag=direct`, 2 GiB: the floor for writing the store), and
# REPEAT (default 3) runs of `scanflow ingest FILE --mem MEM`, each after a `sync` so that no
# run pays for the previous one's writeback; prints every run, the median's points/s, peak
# resident memory and the ratios.
#
#   scripts/bench_ingest.sh            # N=100000000 MEM=1G
#   N=10000000 MEM=256M scripts/bench_ingest.sh
#   KEEP=1 DIR=/data/bench scripts/bench_ingest.sh   # reuse/keep the input file
#
# Then the split ingest (`ingest --shard I/G`, G=SPLIT tasks, default 2, run together here
# with the cores shared out): its time, points/s and ratio to one process, and a check that
# its store holds the same cells (keys, counts, bounds) as one process's. SPLIT=0 skips it.
set -euo pipefail
cd "$(dirname "$0")/.."
N=${N:-100000000}
MEM=${MEM:-1G}
THREADS=${THREADS:-0}
REPEAT=${REPEAT:-3}
DIR=${DIR:-$(mktemp -d -t scanflow-bench-XXXX)}
mkdir -p "$DIR"
cargo build --release --quiet
BIN=$PWD/target/release/scanflow
PLY=$DIR/bench_$N.ply
STORE=$DIR/bench_$N.store
SPLIT=${SPLIT:-2}
cleanup() { rm -rf "$STORE" "$STORE.split" "$STORE.work"; [ -n "${KEEP:-}" ] || rm -f "$PLY" "${PLY%.ply}.truth.json"; }
trap cleanup EXIT
if [ ! -f "$PLY" ]; then
  echo "synthesising $N points into $PLY"
  "$BIN" synth sphere --points "$N" --noise 0.0005 -o "$PLY" --progress none
fi
BYTES=$(stat -c %s "$PLY")
rm -rf "$STORE"

now() { date +%s.%N; }
t0=$(now); cat "$PLY" > /dev/null; t1=$(now)
CAT=$(echo "$t1 - $t0" | bc -l)

DD=$DIR/dd.bin
sync; t0=$(now); dd if=/dev/zero of="$DD" bs=16M count=128 oflag=direct status=none; t1=$(now)
rm -f "$DD"
DISK=$(echo "2 * 1024^3 / ($t1 - $t0)" | bc -l)

LOG=$DIR/ingest.log
TIMES=()
for r in $(seq "$REPEAT"); do
  rm -rf "$STORE"; sync
  t0=$(now)
  "$BIN" ingest "$PLY" -o "$STORE" --mem "$MEM" --threads "$THREADS" --progress json 2> "$LOG" >/dev/null
  t1=$(now)
  TIMES+=("$(echo "$t1 - $t0" | bc -l)")
  printf 'run %d: %.2f s\n' "$r" "${TIMES[-1]}"
done
ING=$(printf '%s\n' "${TIMES[@]}" | sort -g | awk '{a[NR]=$1} END {print a[int((NR + 1) / 2)]}')
PEAK=$(python3 -c 'import json,sys; print(max(json.loads(l).get("peak_rss_bytes",0) for l in open(sys.argv[1]) if l.startswith("{")))' "$LOG")
MEMB=$("$BIN" info "$STORE" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)["store_bytes"])')

if [ "$SPLIT" -gt 0 ]; then
  cores=$(nproc); per=$(( (THREADS > 0 ? THREADS : cores) / SPLIT )); [ "$per" -ge 1 ] || per=1
  rm -rf "$STORE.split" "$STORE.work"; sync
  t0=$(now)
  for i in $(seq 0 $((SPLIT - 1))); do
    "$BIN" ingest "$PLY" -o "$STORE.split" --shard "$i/$SPLIT" --work-dir "$STORE.work" \
      --mem "$MEM" --threads "$per" --progress none > /dev/null &
  done
  wait
  t1=$(now)
  SPLIT_T=$(echo "$t1 - $t0" | bc -l)
  python3 - "$STORE" "$STORE.split" "$N" "$ING" "$SPLIT_T" "$SPLIT" "$per" <<'PY'
import json, sys
a, b = (json.load(open(p + "/manifest.json")) for p in sys.argv[1:3])
n, one, split, g, per = int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5]), sys.argv[6], sys.argv[7]
same = [(c["key"], c["count"], c["bounds"]) for c in a["cells"]] == [(c["key"], c["count"], c["bounds"]) for c in b["cells"]]
print(f"split ingest    {split:8.2f} s   {n / split / 1e6:7.1f} M points/s with {g} tasks of {per} threads together: {split / one:.2f}x one process's time; cells {'the same' if same else 'DIFFER'}")
PY
fi

python3 - "$N" "$BYTES" "$CAT" "$ING" "$PEAK" "$MEM" "$MEMB" "$DISK" <<'PY'
import sys
n, size, cat, ing, peak, mem, store, disk = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5]), sys.argv[6], int(sys.argv[7]), float(sys.argv[8])
units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
budget = float(mem[:-1]) * units[mem[-1].upper()] if mem[-1].upper() in units else float(mem)
print(f"input           {n} points, {size / 2**30:.2f} GiB binary PLY")
print(f"cat > /dev/null {cat:8.2f} s   {size / cat / 2**30:6.2f} GiB/s   {n / cat / 1e6:7.1f} M points/s")
print(f"disk write      {disk / 2**30:8.2f} GiB/s direct: the store alone needs {store / disk:.2f} s")
print(f"scanflow ingest {ing:8.2f} s   {size / ing / 2**30:6.2f} GiB/s   {n / ing / 1e6:7.1f} M points/s (median of the runs)")
print(f"ratio ingest/cat time: {ing / cat:.2f}x, ingest/store-write floor: {ing / (store / disk):.2f}x  (target >= 20 M points/s: {'met' if n / ing >= 20e6 else 'NOT met'})")
print(f"peak RSS        {peak / 2**20:.0f} MiB with --mem {mem}: {peak / budget:.2f} of the budget ({'within' if peak <= budget + (64 << 20) else 'OVER'} budget + 64 MiB margin)")
print(f"store           {store / 2**30:.2f} GiB ({store / n:.1f} bytes/point)")
print("fair? cat only reads the bytes; ingest reads them twice (count, scatter; plus a 1/64 sample for bounds), sorts, compresses and writes them.")
PY
