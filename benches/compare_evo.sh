#!/usr/bin/env bash
# evo_ape against `sgm run`'s ATE on the TUM files of a run (default: a fresh quickstart run).
# Usage: benches/compare_evo.sh [RUN_DIR]
exec "$(dirname "$0")/with_venv.sh" "$(dirname "$0")/compare_evo.py" "$@"
