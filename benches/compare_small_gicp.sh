#!/usr/bin/env bash
# small_gicp vs `sgm icp`, same clouds, same run, one thread.
exec "$(dirname "$0")/with_venv.sh" "$(dirname "$0")/compare_small_gicp.py" "$@"
