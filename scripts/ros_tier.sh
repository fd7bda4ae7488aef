#!/usr/bin/env bash
# The `ros` tier of `make test` / `make test-jazzy` with the given Python: the test files two at
# a time on the two cores (pytest-xdist by file, so a module's shared fixtures stay in one
# process; each worker in a ROS domain of its own, test/conftest.py), then the tests marked
# `alone` (figures that depend on a quiet machine) one at a time. Both parts print their ten
# slowest tests. Usage: scripts/ros_tier.sh [--no-alone] PYTHON [PYTEST ARGS...] (the arguments
# go to the first part; --no-alone leaves out the second)
set -euo pipefail
alone=yes
if [ "${1:-}" = --no-alone ]; then
  alone=no
  shift
fi
python=$1
shift
here=$(cd "$(dirname "$0")" && pwd)
status=0
"$here/ros_env.sh" --private "$python" -m pytest -q -n 2 --dist loadfile \
  -m "ros and not alone" --durations=10 "$@" test || status=$?
if [ $alone = yes ]; then
  "$here/ros_env.sh" --private "$python" -m pytest -q -m "ros and alone" --durations=10 test \
    || status=$?
fi
exit $status
