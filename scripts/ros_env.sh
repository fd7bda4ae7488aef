#!/usr/bin/env bash
# Run a command with the ROS settings this workplace needs: discovery on loopback only, a domain
# of its own unless one is given, and the quick-discovery Fast DDS profile.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$(( (RANDOM % 90) + 10 ))}
export FASTDDS_DEFAULT_PROFILES_FILE=${FASTDDS_DEFAULT_PROFILES_FILE:-$root/config/fastdds_fast_discovery.xml}
exec "$@"
