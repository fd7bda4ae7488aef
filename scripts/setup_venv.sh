#!/usr/bin/env bash
# Create .venv (Python 3.11) and install requirements.txt and the package (editable). Re-running
# is a no-op while requirements.txt, setup.py and package.xml are unchanged.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3.11}
stamp=.venv/.installed
want=$(cat requirements.txt setup.py package.xml | sha256sum | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  exit 0
fi
if ! command -v "$PYTHON" >/dev/null 2>&1; then
  echo "setup_venv: $PYTHON not found; the ROS 2 Kilted wheels need CPython 3.11" >&2
  exit 1
fi
[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -r requirements.txt
.venv/bin/python -m pip install --quiet --no-deps -e .
echo "$want" > "$stamp"
echo "setup_venv: .venv ready"
