#!/usr/bin/env bash
# Hexahedral meshing: scanflow hexmesh (CubeCover-style: frames, integer-grid parameterisation,
# extraction, pillowing, relaxation) and gmsh's all-hex route (tetrahedra, each split into 4
# hexahedra) on the same closed surfaces, same machine, same run.
#
# What it measures: scripts/hex_peers.py writes the surfaces in SHAPES (binary PLY via trimesh,
# and an STL of the same triangles for gmsh): box 2 x 1.5 x 1, cylinder r 1 h 2 (128 sections),
# torus R 1 r 0.35 (96 x 48 sections). For each shape, and for the 156K-tet cases in K156:
#   scanflow hexmesh SURF.ply -o OUT.vtk --report R.json --threads THREADS [HEX_OPTS_<shape>]
#     under /usr/bin/time -v (wall seconds of the whole run, tetrahedralisation and I/O included,
#     and peak RSS) and PEER_TIMEOUT; tets, stage seconds, polycube iterations, hexes, min/mean
#     scaled Jacobian and inverted hexes from the report; then scripts/hex_check.py OUT.vtk
#     --reference SURF.ply (independent scaled Jacobian, boundary-to-surface distances) and on a
#     .msh copy of OUT (gmsh's own minSJ). --keep-inverted, so an inverted mesh is measured too.
#   gmsh, for each factor F in GMSH_FACTORS (default 1 and 2): the STL classified into patches,
#     a volume on them, mesh size F x scanflow's hex edge, Mesh.SubdivisionAlgorithm = 2
#     (tet -> 4 hexes, so F = 2 gives hexes about as long as scanflow's), generate(3), in a
#     subprocess under PEER_TIMEOUT; wall = the meshing alone (writing excluded); its .msh goes
#     through the same hex_check.py. Failures and timeouts are rows, not crashes.
#   156K: the CubeCover paper (Nieser, Reitebuch, Polthier, SGP 2011) parameterised a 156K-tet
#     model in 2 min 43 s; K156 names shapes and --scale values giving about 156K tets (the
#     report's tets), and the ratio 163 s / scanflow's wall is printed, as a ratio to a published
#     2011 figure (target >= 10x, <= 16.3 s), not a same-machine comparison.
#
# usage: scripts/bench_hex.sh
#   SHAPES="box cylinder torus"  THREADS=2  PEER_TIMEOUT=600  SAMPLES=20000 (hex_check.py)
#   HEX_OPTS_box=""  HEX_OPTS_cylinder=""  HEX_OPTS_torus="--scale 0.1"   extra hexmesh options
#   K156="cylinder:0.16 box:0.125"   SHAPE:SCALE for the 156K-tet cases (K156= skips them)
#   TETS="octopus:PATH fandisk:PATH"   NAME:FILE tetrahedral meshes meshed at the default edge,
#                    measured against their own boundary, scanflow only (TETS= skips them;
#                    the defaults are the test data beside the repository, skipped if absent)
#   GMSH_FACTORS="1 2"   gmsh mesh size / scanflow's hex edge;  PEERS=0  scanflow only
#   BUILD=0          use the existing target/release/scanflow;  SCANFLOW=PATH  binary to measure
#   KEEP=DIR         keep surfaces, meshes, reports, logs and rows.jsonl in DIR
set -euo pipefail
cd "$(dirname "$0")/.."
export PYTHONDONTWRITEBYTECODE=1   # no __pycache__ in scripts/
SHAPES=${SHAPES:-box cylinder torus}
THREADS=${THREADS:-2}
PEERS=${PEERS:-1}
PEER_TIMEOUT=${PEER_TIMEOUT:-600}
SAMPLES=${SAMPLES:-20000}
K156=${K156-cylinder:0.16 box:0.125}
TETS=${TETS-octopus:../shared/data/tetmesh/octopus-low.mesh fandisk:../shared/data/tetmesh/fandisk.mesh}
GMSH_FACTORS=${GMSH_FACTORS:-1 2}
HEX_OPTS_box=${HEX_OPTS_box-}
HEX_OPTS_cylinder=${HEX_OPTS_cylinder-}
HEX_OPTS_torus=${HEX_OPTS_torus---scale 0.1}

python3 -c 'import trimesh, numpy, meshio, gmsh, scipy' 2>/dev/null ||
  python3 -m pip install --quiet --disable-pip-version-check trimesh numpy meshio gmsh scipy || {
    echo "pip could not install trimesh numpy meshio gmsh scipy (no index reachable? Python $(python3 -V 2>&1))" >&2; exit 1; }
python3 -c 'import trimesh, numpy, meshio, gmsh, scipy' || { echo "trimesh, meshio, gmsh or scipy does not import" >&2; exit 1; }

if [ -n "${SCANFLOW:-}" ]; then BIN=$SCANFLOW
else
  BIN=$PWD/target/release/scanflow
  [ "${BUILD:-1}" = 0 ] || cargo build --release --quiet
fi
[ -x "$BIN" ] || { echo "no scanflow binary at $BIN" >&2; exit 1; }
"$BIN" hexmesh --help > /dev/null 2>&1 || { echo "$BIN has no 'hexmesh' command" >&2; exit 1; }
QUIET=()
! "$BIN" hexmesh --help | grep -q -- --progress || QUIET=(--progress none)
[ -x /usr/bin/time ] || { echo "needs GNU time at /usr/bin/time (apt-get install time)" >&2; exit 1; }

if [ -n "${KEEP:-}" ]; then TMP=$KEEP; mkdir -p "$TMP"
else TMP=$(mktemp -d -t scanflow-hex-XXXX); trap 'rm -rf "$TMP"' EXIT; fi
ROWS=$TMP/rows.jsonl
: > "$ROWS"

all_shapes=$SHAPES
for k in $K156; do all_shapes="$all_shapes ${k%%:*}"; done
all_shapes=$(echo $all_shapes | tr ' ' '\n' | awk '!seen[$0]++' | paste -sd, -)
echo "shapes: $SHAPES; 156K cases: ${K156:-none}; gmsh size factors: $GMSH_FACTORS; $THREADS threads, $(nproc) cores; scratch $TMP"
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?) (a busy machine slows every side)"
python3 scripts/hex_peers.py gen "$TMP" --shapes "$all_shapes" > "$TMP/shapes.json"

# run_case CASE INPUT HEXMESH_OPTION...   (INPUT: a surface, or a tet mesh: no gmsh row then)
run_case() {
  local case=$1 surf=$2; shift 2
  local out=$TMP/${case}_scanflow rc=0
  cat "$surf" > /dev/null   # warm page cache
  echo "[$case] scanflow hexmesh $* ..." >&2
  /usr/bin/time -v -o "$out.time" timeout "$PEER_TIMEOUT" "$BIN" hexmesh "$surf" -o "$out.vtk" \
    --report "$out.json" --threads "$THREADS" --keep-inverted "${QUIET[@]}" "$@" > "$out.log" 2>&1 || rc=$?
  python3 scripts/hex_peers.py scanflow --case "$case" --surface "$surf" --mesh "$out.vtk" --report "$out.json" \
    --time "$out.time" --rc "$rc" --log "$out.log" --timeout "$PEER_TIMEOUT" --samples "$SAMPLES" >> "$ROWS"
  [ "$PEERS" != 0 ] || return 0
  case $surf in *.mesh|*.msh|*.vtk) return 0 ;; esac
  local edge
  edge=$(tail -n 1 "$ROWS" | python3 -c 'import json, sys; r = json.load(sys.stdin); print(r.get("scale") or "")')
  if [ -z "$edge" ]; then echo "[$case] no hex edge from scanflow's report: gmsh skipped" >&2; return 0; fi
  for f in $GMSH_FACTORS; do
    local size
    size=$(python3 -c "print($f * $edge)")
    echo "[$case] gmsh, size $size ($f x hex edge) ..." >&2
    python3 scripts/hex_peers.py gmsh --case "$case" --surface "$surf" --size "$size" --factor "$f" \
      --out "$TMP/${case}_gmsh_x$f" --threads "$THREADS" --timeout "$PEER_TIMEOUT" --samples "$SAMPLES" >> "$ROWS" || {
      echo "{\"case\": \"$case\", \"tool\": \"gmsh x$f\", \"status\": \"hex_peers.py failed\"}" >> "$ROWS"; }
  done
}

for shape in $SHAPES; do
  var=HEX_OPTS_$shape
  read -r -a opts <<< "${!var-}"
  run_case "$shape" "$TMP/$shape.ply" "${opts[@]}"
done
for k in $K156; do
  run_case "${k%%:*}-156K" "$TMP/${k%%:*}.ply" --scale "${k##*:}"
done
for k in $TETS; do
  if [ -f "${k#*:}" ]; then run_case "${k%%:*}" "${k#*:}"
  else echo "[${k%%:*}] ${k#*:} not found: skipped" >&2; fi
done

echo
python3 scripts/hex_peers.py table "$ROWS"
echo
echo "fairness: same surfaces, same machine. scanflow's wall is the whole process (reading the PLY,"
echo "tetrahedralising it, frames, parameterisation, extraction, pillowing, relaxation, writing the"
echo "VTK) with --threads $THREADS; gmsh's is its meshing in process (classify, geometry, surface and"
echo "volume mesh, subdivision; writing excluded), General.NumThreads $THREADS, default 3D Delaunay"
echo "(serial). gmsh's tets are its hexes / 4. min_SJ, mean_SJ, inv (SJ <= 0) and the distances"
echo "(sampled symmetric Hausdorff max and mean, over the bounding-box diagonal) all come from"
echo "scripts/hex_check.py; gmshSJ is gmsh's own minSJ of the same file (a different measure)."
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo ?)"
[ -z "${KEEP:-}" ] || echo "rows: $ROWS"
