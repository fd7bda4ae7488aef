#!/usr/bin/env bash
# Run a command with the ROS settings this workplace needs: discovery on loopback only and the
# quick-discovery Fast DDS profile. Usage: scripts/ros_env.sh [--private] COMMAND [ARGS...]
# The domain is the user's ROS_DOMAIN_ID (default 0, as in ROS), so a bringup in one terminal and
# a client in another find each other; --private (the test targets) picks a random domain 10-99
# of its own, so a test run never hears the user's robot or another run.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
if [ "${1:-}" = --private ]; then
  shift
  export ROS_DOMAIN_ID=$(( (RANDOM % 90) + 10 ))
else
  export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-0}
fi
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export FASTDDS_DEFAULT_PROFILES_FILE=${FASTDDS_DEFAULT_PROFILES_FILE:-$root/config/fastdds_fast_discovery.xml}
exec "$@"
