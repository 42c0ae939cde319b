#!/usr/bin/env bash
# Runs a comparison script in target/bench-venv with the reference tools installed (created on
# first use) after building `sgm` in release mode. Usage: benches/with_venv.sh SCRIPT.py [ARGS]
set -euo pipefail
cd "$(dirname "$0")/.."
venv=target/bench-venv
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet "gtsam==4.3.0" "small_gicp==1.0.1" evo numpy scipy
fi
cargo build --release --quiet --bin sgm
script=$1
shift
exec "$venv/bin/python" "$script" "$@"
