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
# Added later than the venv may be: KISS-ICP and the rosbags reader it uses.
"$venv/bin/python" -c "import kiss_icp, rosbags" 2>/dev/null || "$venv/bin/pip" install --quiet "kiss-icp==1.3.0" "rosbags==0.11.9"
cargo build --release --quiet --bin sgm
script=$1
shift
exec "$venv/bin/python" "$script" "$@"
