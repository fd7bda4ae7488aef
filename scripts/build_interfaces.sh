#!/usr/bin/env bash
# Build an interface package (default continuum_statics_interfaces: the MoveTip action; also
# vendor/tf2_msgs) into a venv with plain cmake, from the ros-rosidl-* / ros-ament-cmake* wheels of requirements*.txt (no colcon, no ROS
# installation). The venv is the install prefix, as for the ros-* wheels themselves: the generated
# Python package lands in its site-packages and the typesupport libraries next to the wheels'.
# Usage: scripts/build_interfaces.sh [VENV] [PACKAGE_DIR]   (default .venv
# continuum_statics_interfaces)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=$(cd "${1:-.venv}" && pwd)
PY="$VENV/bin/python"
PACKAGE_DIR=${2:-continuum_statics_interfaces}
PACKAGE=$(basename "$PACKAGE_DIR")
# The wheels' exported cmake files carry include paths of the machine that built them
# (/opt/python/cp311-cp311/...): point them at this interpreter's headers and numpy's.
include=$("$PY" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
numpy_include=$("$PY" -c "import numpy; print(numpy.get_include())")
{ grep -l '/opt/python/cp311-cp311' "$VENV"/share/*/cmake/*.cmake 2>/dev/null || true; } |
while read -r file; do
  sed -i -e "s#/opt/python/cp311-cp311/include/python3.11#$include#g" \
         -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$numpy_include#g" \
         "$file"
done
build=$(mktemp -d)
trap 'rm -rf "$build"' EXIT
PATH="$VENV/bin:$PATH" cmake -S "$PACKAGE_DIR" -B "$build" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_INSTALL_PREFIX="$VENV" -DCMAKE_PREFIX_PATH="$VENV" -DPython3_EXECUTABLE="$PY" \
  -DBUILD_TESTING=OFF > "$build/configure.log" 2>&1 || { tail -40 "$build/configure.log" >&2; exit 1; }
PATH="$VENV/bin:$PATH" cmake --build "$build" -j "$(nproc)" > "$build/build.log" 2>&1 \
  || { tail -40 "$build/build.log" >&2; exit 1; }
cmake --install "$build" > /dev/null
"$PY" -c "import $PACKAGE" && echo "build_interfaces: $PACKAGE installed into $VENV"
