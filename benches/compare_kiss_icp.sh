#!/usr/bin/env bash
# KISS-ICP vs SGM's LiDAR-inertial front end, same sweeps, same run, one thread each.
exec "$(dirname "$0")/with_venv.sh" "$(dirname "$0")/compare_kiss_icp.py" "$@"
