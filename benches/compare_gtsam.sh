#!/usr/bin/env bash
# GTSAM Levenberg–Marquardt vs `sgm optimize`, same files, same run. Usage: [--outliers]
exec "$(dirname "$0")/with_venv.sh" "$(dirname "$0")/compare_gtsam.py" "$@"
