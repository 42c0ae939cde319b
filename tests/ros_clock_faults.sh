#!/usr/bin/env bash
# Clock faults against Debian's real ROS 1 tools (issue "field-ros"): one `sgm ros` node
# (quickstart's alpha) under a rosmaster on 127.0.0.1, fed by `rosbag play`.
#   1. one nav_msgs/Odometry stamped years ahead, published by `rostopic pub` before the bag:
#      an outlier, dropped; every frame of the bag is still assembled;
#   2. the bag played a second time right after (as `rosbag play --loop` does): the stamps jump
#      back 45 s, the timeline restarts once, and the second pass is mapped too;
#   3. with `/use_sim_time` true and `rosbag play --clock`: the node follows /clock.
# Every process started here is stopped by PID.
set -euo pipefail
cd "$(dirname "$0")/.."
SGM=${SGM:-target/release/sgm}
PY=/usr/bin/python3
WORK=$(mktemp -d /tmp/sgm-clock.XXXXXX)
export ROS_MASTER_URI=http://127.0.0.1:11321 ROS_IP=127.0.0.1 ROS_HOME=$WORK/roshome
mkdir -p "$ROS_HOME"
PIDS=()
cleanup() {
  for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${PIDS[@]}"; do wait "$pid" 2>/dev/null || true; done
  [ "${CLOCK_KEEP:-0}" = 1 ] && echo "kept $WORK" || rm -rf "$WORK"
}
trap cleanup EXIT
# shellcheck source=tests/ros_common.sh
. tests/ros_common.sh
fail() { echo "ros clock faults FAILED: $*" >&2; exit 1; }
# quickstart cut to 45 s: nothing here needs an alignment, and the bag is played three times.
short_quickstart 45.0 "$WORK/quickstart_45s.toml" || fail "quickstart cut to 45 s"
"$SGM" run "$WORK/quickstart_45s.toml" --quiet --out "$WORK/run" --bag-out "$WORK/bags" --no-result-bag >/dev/null \
  || fail "sgm run quickstart (45 s)"
# Clouds in the bag: every one must become a frame.
FRAMES=$(bag_messages "$WORK/bags/alpha.bag" /alpha/points) || fail "rosbag info alpha.bag"
(umask 077 && head -c 32 /dev/urandom | od -An -vtx1 | tr -d ' \n' > "$WORK/team.key")
ss -ltn | grep -q ':11321 ' && fail "port 11321 busy"
rosmaster --core -p 11321 >"$WORK/master.log" 2>&1 & PIDS+=($!)
for _ in $(seq 100); do rosnode list >/dev/null 2>&1 && break; sleep 0.1; done
TOPICS=(/alpha/points /alpha/labels /alpha/camera_info /alpha/odometry /tf_static)
start_node() {
  SGM__COMMS__TEAM_KEY_FILE=$WORK/team.key NO_COLOR=1 "$SGM" ros --robot alpha --scenario quickstart __ns:=/alpha \
    >"$WORK/alpha.$1.log" 2>&1 & NODE=$!; PIDS+=($NODE)
  for _ in $(seq 100); do rosnode list 2>/dev/null | grep -x /alpha/sgm_alpha >/dev/null && return 0; sleep 0.2; done
  cat "$WORK/alpha.$1.log"; fail "the node did not come up"
}
status() {
  sleep 2
  timeout 20 rostopic echo -n 1 /alpha/sgm/status | $PY -c '
import sys, yaml
print(yaml.safe_load(sys.stdin.read().split("---")[0])["data"])' > "$WORK/$1.json" || fail "status"
}

echo "== a stamp years ahead, then the bag twice in a row"
start_node glitch
rostopic pub -1 /alpha/odometry nav_msgs/Odometry \
  "{header: {stamp: {secs: 2000000000, nsecs: 0}, frame_id: alpha/odom}, child_frame_id: alpha/base_link, pose: {pose: {orientation: {w: 1.0}}}}" >/dev/null
for pass in 1 2; do
  rosbag play -q -r 3 --wait-for-subscribers "$WORK/bags/alpha.bag" --topics "${TOPICS[@]}" >/dev/null 2>&1 \
    || fail "rosbag play, pass $pass"
done
status glitch
$PY - "$WORK/glitch.json" "$FRAMES" <<'PY' || fail "see above"
import json, sys
s = json.load(open(sys.argv[1]))
n = int(sys.argv[2])
t, sync = s["timeline"], s["sync"]
print(f"  {sync['frames']} frames of 2 × {n} ({sync['at_restart']} waiting at the restart), "
      f"{t['outliers']} outlier(s), {t['restarts']} restart(s), last jump {t['last_jump']}")
assert t["outliers"] >= 1, t
assert t["restarts"] == 1, t
assert sync["frames"] + sync["at_restart"] >= 2 * n - 2, sync
assert sync["frames"] >= 2 * n - 5, sync
assert sync["out_of_order"] == 0, sync
PY
grep -q "timeline restarts" "$WORK/alpha.glitch.log" || fail "the restart was not logged"
kill -INT "$NODE"; wait "$NODE" || fail "SIGINT"

echo "== use_sim_time: /clock followed"
rosparam set /use_sim_time true
start_node simtime
rosbag play -q -r 3 --clock --wait-for-subscribers "$WORK/bags/alpha.bag" --topics "${TOPICS[@]}" >/dev/null 2>&1 \
  || fail "rosbag play --clock"
status simtime
$PY - "$WORK/simtime.json" "$FRAMES" <<'PY' || fail "see above"
import json, sys
s = json.load(open(sys.argv[1]))
print(f"  {s['accepted']['clock']} /clock messages, {s['sync']['frames']} frames, robot clock at {s['stamp']}")
assert s["accepted"]["clock"] > 100, s["accepted"]
assert s["sync"]["frames"] == int(sys.argv[2]), s["sync"]
PY
grep -q "use_sim_time: following /clock" "$WORK/alpha.simtime.log" || fail "not following /clock"
echo "ros clock faults: all passed"
