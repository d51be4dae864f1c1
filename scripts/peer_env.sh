# Shared setup of the benchmarks that compare scanflow with Open3D; sourced, not run.
#
#   need_open3d PKG...   make `import open3d PKG...` work (pip, then Open3D's shared-library
#                        dependencies from apt when its import still fails); zstandard too, or
#                        the zstd command, to read stores back
#   scanflow_bin CMD     set BIN to $SCANFLOW, or target/release/scanflow (built unless BUILD=0),
#                        and check that `scanflow CMD` has --normals

need_open3d() {
  local mods
  mods=$(printf ', %s' "$@")
  if ! python3 -c "import open3d$mods" 2>/dev/null; then
    python3 -m pip install --quiet --disable-pip-version-check open3d "$@" || {
      echo "pip could not install open3d $* (no index reachable? Python $(python3 -V 2>&1))" >&2; exit 1; }
    if ! python3 -c "import open3d" 2>/dev/null && command -v apt-get >/dev/null; then
      apt-get install -y -qq libgomp1 libusb-1.0-0 >/dev/null 2>&1 || true   # Open3D's shared-library deps
    fi
    python3 -c "import open3d" || { echo "open3d does not import" >&2; exit 1; }
  fi
  python3 -c "import zstandard" 2>/dev/null || command -v zstd >/dev/null ||
    python3 -m pip install --quiet --disable-pip-version-check zstandard || true
}

scanflow_bin() {
  if [ -n "${SCANFLOW:-}" ]; then BIN=$SCANFLOW
  else
    BIN=$PWD/target/release/scanflow
    [ "${BUILD:-1}" = 0 ] || cargo build --release --quiet
  fi
  [ -x "$BIN" ] || { echo "no scanflow binary at $BIN" >&2; exit 1; }
  "$BIN" "$1" --help | grep -q -- '--normals' || {
    echo "$BIN $1 has no --normals (normal estimation): too old" >&2; exit 1; }
}
