#!/usr/bin/env bash
# Side-by-side: GTSAM Levenberg–Marquardt (Python wheel, default parameters, prior on the first
# pose as in GTSAM's g2o examples) and `sgm optimize` on the same files, in one run.
# Usage: benches/compare_gtsam.sh [--outliers]   (venv in target/gtsam-venv, created on first use)
set -euo pipefail
cd "$(dirname "$0")/.."
venv=target/gtsam-venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet "gtsam==4.3.0" numpy
fi
cargo build --release --quiet --bin sgm
exec "$venv/bin/python" benches/compare_gtsam.py "$@"
