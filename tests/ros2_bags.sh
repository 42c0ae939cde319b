#!/usr/bin/env bash
# ROS 2 recordings through `sgm replay`, against an independent writer: our ROS 1 bags converted
# by the `rosbags` Python package (`rosbags-convert`, ROS 2 Humble message types, installed from
# PyPI into a venv here) to rosbag2's MCAP and sqlite3 storages replay to the same report.json as
# the ROS 1 bags, byte for byte. Two missions: quickstart (clouds, label images, camera info,
# odometry, ground truth, tf_static) and quickstart on the robots' own odometry (their IMU and
# sweeps, over the mission's first 30 s, through MCAP: the storages share the decoding). Then what
# a user can get wrong: a recording whose metadata.yaml disagrees with its
# database, and one cut short, each refused naming the file and topic.
# Usage: SGM=target/debug/sgm bash tests/ros2_bags.sh
set -euo pipefail
cd "$(dirname "$0")/.."
SGM=${SGM:-target/release/sgm}
WORK=$(mktemp -d /tmp/sgm-ros2-bags.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
# shellcheck source=tests/ros_common.sh
. tests/ros_common.sh
fail() { echo "ros2_bags FAILED: $*" >&2; exit 1; }
export RUST_LOG=error
short_quickstart 30.0 "$WORK/quickstart_30s.toml" || fail "quickstart cut to 30 s"

venv=target/ros2-venv
if ! "$venv/bin/python" -c "import rosbags" 2>/dev/null; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet "rosbags==0.11.9"
fi
convert() { # SRC.bag DST STORAGE
  "$venv/bin/rosbags-convert" --src "$1" --dst "$2" --dst-storage "$3" \
    --src-typestore ros1_noetic --dst-typestore ros2_humble >/dev/null
}

mission() { # NAME SCENARIO "STORAGES", then environment for `sgm run`
  local name=$1 scenario=$2 storages=$3
  shift 3
  env "$@" "$SGM" run "$scenario" --quiet --out "$WORK/$name/run" --bag-out "$WORK/$name/ros1" --no-result-bag >/dev/null
  local bags=()
  for robot in alpha bravo; do bags+=(--bag "$WORK/$name/ros1/$robot.bag"); done
  env "$@" "$SGM" replay "${bags[@]}" --config "$scenario" --quiet --out "$WORK/$name/replay-ros1" --no-result-bag >/dev/null
  for storage in $storages; do
    bags=()
    for robot in alpha bravo; do
      convert "$WORK/$name/ros1/$robot.bag" "$WORK/$name/$storage/$robot" "$storage"
      bags+=(--bag "$WORK/$name/$storage/$robot")
    done
    env "$@" "$SGM" replay "${bags[@]}" --config "$scenario" --quiet --out "$WORK/$name/replay-$storage" --no-result-bag >/dev/null
    cmp "$WORK/$name/replay-ros1/report.json" "$WORK/$name/replay-$storage/report.json" \
      || fail "$name: the $storage recording's report.json differs from the ROS 1 bags'"
    echo "ros2_bags: $name: $storage replay report.json identical to the ROS 1 replay's"
  done
}

mission synthetic_odometry quickstart "mcap sqlite3"
mission own_odometry "$WORK/quickstart_30s.toml" mcap \
  SGM__ODOMETRY__SOURCE=internal SGM__IMU__ENABLED=true SGM__LIDAR__SWEEP_S=0.1

# A storage file alone (no metadata.yaml) is read by its magic too.
rec=$WORK/synthetic_odometry/sqlite3
"$SGM" replay --bag "$rec/alpha/alpha.db3" --bag "$rec/bravo/bravo.db3" --config quickstart --quiet \
  --out "$WORK/alone" --no-result-bag >/dev/null
cmp "$WORK/synthetic_odometry/replay-ros1/report.json" "$WORK/alone/report.json" \
  || fail "the .db3 files alone replay differently"
echo "ros2_bags: .db3 files alone: report.json identical"

# metadata.yaml that disagrees with its database: refused, naming the recording and the topic.
cp -r "$rec/alpha" "$WORK/disagrees"
sed -i '0,/message_count: 180/s//message_count: 181/' "$WORK/disagrees/metadata.yaml"
out=$("$SGM" replay --bag "$WORK/disagrees" --bag "$rec/bravo" --config quickstart --quiet \
  --out "$WORK/disagrees-out" --no-result-bag 2>&1) && fail "a disagreeing metadata.yaml was accepted"
grep -q "disagrees.*metadata.yaml disagrees with the storage on topic /alpha/.*declares 181 messages, the storage holds 180" <<<"$out" \
  || fail "a disagreeing metadata.yaml: unexpected message: $out"
echo "ros2_bags: a disagreeing metadata.yaml is refused: $(grep -o 'metadata.yaml disagrees.*' <<<"$out" | head -1)"

# An MCAP file cut short: refused, naming the file.
mcap=$WORK/synthetic_odometry/mcap/alpha/alpha.mcap
head -c $(($(stat -c %s "$mcap") / 2)) "$mcap" >"$WORK/cut.mcap"
out=$("$SGM" replay --bag "$WORK/cut.mcap" --bag "$rec/bravo" --config quickstart --quiet \
  --out "$WORK/cut-out" --no-result-bag 2>&1) && fail "a cut MCAP file was accepted"
grep -q "cut.mcap" <<<"$out" || fail "a cut MCAP file: unexpected message: $out"
echo "ros2_bags: a cut MCAP file is refused: $(grep -o 'cut.mcap.*' <<<"$out" | head -1)"
echo "ros2_bags: ok"
