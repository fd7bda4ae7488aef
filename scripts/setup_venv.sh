#!/usr/bin/env bash
# Create a venv (Python 3.11; default .venv) and install a requirements file (default
# requirements.txt) and the package (editable). Re-running is a no-op while the requirements file,
# setup.py and package.xml are unchanged. The Jazzy route: VENV=.venv-jazzy
# REQUIREMENTS=requirements-jazzy.txt scripts/setup_venv.sh
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3.11}
VENV=${VENV:-.venv}
REQUIREMENTS=${REQUIREMENTS:-requirements.txt}
stamp=$VENV/.installed
want=$(cat "$REQUIREMENTS" setup.py package.xml scripts/build_interfaces.sh \
  continuum_statics_interfaces/CMakeLists.txt continuum_statics_interfaces/package.xml \
  continuum_statics_interfaces/action/*.action continuum_statics_interfaces/msg/*.msg vendor/tf2_msgs/CMakeLists.txt \
  vendor/tf2_msgs/package.xml vendor/tf2_msgs/msg/*.msg | sha256sum | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  exit 0
fi
if ! command -v "$PYTHON" >/dev/null 2>&1; then
  echo "setup_venv: $PYTHON not found; the ROS 2 wheels need CPython 3.11" >&2
  exit 1
fi
[ -x "$VENV/bin/python" ] || "$PYTHON" -m venv "$VENV"
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install --quiet -r "$REQUIREMENTS"
"$VENV/bin/python" -m pip install --quiet --no-deps -e .
# The MoveTip action (continuum_statics_interfaces) with plain cmake into the venv prefix.
scripts/build_interfaces.sh "$VENV"
# tf2_msgs (TFMessage, for /tf) has no wheel: the same route builds vendor/tf2_msgs unless the
# venv already has it (a ROS installation's, or a wheel one day).
"$VENV/bin/python" -c 'import tf2_msgs' 2>/dev/null || scripts/build_interfaces.sh "$VENV" vendor/tf2_msgs
# Compile the numba kernels once into their cache (__pycache__ in the source tree, or
# NUMBA_CACHE_DIR), in two worker processes, printing each kernel's compile time: every later
# process loads them in ~0.2 s instead of compiling them.
"$VENV/bin/python" -m continuum_statics warmup
echo "$want" > "$stamp"
echo "setup_venv: $VENV ready"
