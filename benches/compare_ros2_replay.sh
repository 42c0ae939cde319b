#!/usr/bin/env bash
# `sgm replay` on ROS 2 recordings against ROS 1 bags of the same missions: quickstart and
# outdoor_two_robots recorded as ROS 1 bags (`sgm run --bag-out`), converted by rosbags-convert
# (PyPI, ROS 2 Humble types) to MCAP and to sqlite3, each replayed ROUNDS times (default 5), the
# three formats taking turns, best wall time each; the reports must be byte-identical.
# Usage: benches/compare_ros2_replay.sh [ROUNDS]
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-5}
venv=target/bench-venv
if ! "$venv/bin/python" -c "import rosbags" 2>/dev/null; then
  [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet "rosbags==0.11.9"
fi
cargo build --release --quiet --bin sgm
SGM=target/release/sgm
WORK=$(mktemp -d /tmp/sgm-ros2-replay.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
export RUST_LOG=error

echo "| mission | simulated | ROS 1 bags | MCAP | sqlite3 | report.json |"
echo "|---|---|---|---|---|---|"
for scenario in quickstart outdoor_two_robots; do
  "$SGM" run "$scenario" --quiet --out "$WORK/$scenario/run" --bag-out "$WORK/$scenario/ros1" --no-result-bag >/dev/null
  robots=$(cd "$WORK/$scenario/ros1" && ls ./*.bag | sed 's|^\./||; s|\.bag$||')
  declare -A bags=()
  for format in ros1 mcap sqlite3; do bags[$format]=""; done
  for robot in $robots; do
    bags[ros1]+=" --bag $WORK/$scenario/ros1/$robot.bag"
    for storage in mcap sqlite3; do
      "$venv/bin/rosbags-convert" --src "$WORK/$scenario/ros1/$robot.bag" --dst "$WORK/$scenario/$storage/$robot" \
        --dst-storage "$storage" --src-typestore ros1_noetic --dst-typestore ros2_humble >/dev/null
      bags[$storage]+=" --bag $WORK/$scenario/$storage/$robot"
    done
  done
  declare -A best=()
  for format in ros1 mcap sqlite3; do best[$format]=999999999; done
  for _ in $(seq "$rounds"); do
    for format in ros1 mcap sqlite3; do
      start=$(date +%s%N)
      # shellcheck disable=SC2086
      "$SGM" replay ${bags[$format]} --config "$scenario" --quiet --out "$WORK/$scenario/replay-$format" --no-result-bag >/dev/null
      took=$((($(date +%s%N) - start) / 1000000))
      ((took < best[$format])) && best[$format]=$took
    done
  done
  same=identical
  for storage in mcap sqlite3; do
    cmp -s "$WORK/$scenario/replay-ros1/report.json" "$WORK/$scenario/replay-$storage/report.json" || same="DIFFERS ($storage)"
  done
  sim=$(python3 -c "import json; print(json.load(open('$WORK/$scenario/replay-ros1/report.json'))['sim_s'])")
  row="| $scenario | ${sim} s |"
  for format in ros1 mcap sqlite3; do
    row+=$(awk -v ms="${best[$format]}" -v sim="$sim" 'BEGIN { printf " %.2f s (%.0f×) |", ms / 1000, sim * 1000 / ms }')
  done
  echo "$row $same |"
  unset bags best
done
