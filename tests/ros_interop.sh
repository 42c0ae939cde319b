#!/usr/bin/env bash
# Interop against Debian's real ROS 1 (ros-core: rosmaster, rostopic, rosbag, rosnode), run by
# .ci/run after the Rust tests. Needs `sgm` built (release) and the ROS packages installed.
#   1. (done by .ci/run's `cargo test` with SGM_ROS_INTEROP=1: md5sums against `rosmsg md5`);
#   2. `sgm run quickstart --bag-out`: our bags pass `rosbag info` and `rosbag check`;
#   3. the shipped ROS package (bridge/ros/sgm) as the book's step by step uses it: on
#      ROS_PACKAGE_PATH, `sgm` on PATH; roslaunch's own check of two_robots.launch passes and
#      `roslaunch --nodes` names /alpha/sgm_alpha and /bravo/sgm_bravo; one `roslaunch sgm
#      robot.launch` per robot (alpha and bravo, their own namespaces, configured by the
#      package's config/*.toml, points and odometry remapped to velodyne_points and Odometry)
#      starts the two `sgm ros` processes under a rosmaster on 127.0.0.1, fed by Debian's
#      `rosbag play` of those bags at 3x with the topics renamed to match, the team key in a file
#      made as the book says (mode 600, team_key_file:=): both align through
#      the master; `rostopic echo` sees their MarkerArray, Path and status; every frame accepted;
#   4. malformed messages from `rostopic pub` (unknown encoding, wrong frame, truncated cloud)
#      are refused and counted while the node keeps running; SIGINT to roslaunch stops its node;
#   5. a bag recorded by Debian's `rosbag record` (lz4 chunks) of that traffic replays through
#      `sgm replay` and both robots align;
#   6. as root: the two nodes again (plain `sgm ros`, SGM__COMMS__TEAM_KEY_FILE), each in its
#      own network namespace joined by a veth pair, each fed by a rospy script
#      (tests/ros_feed.py) in its namespace, so everything between the robots crosses a
#      network: both align, and the veth counters show the traffic.
# Everything listens on 127.0.0.1 (or the namespaces' private veth addresses) and every process
# started here is stopped by PID; the namespaces are deleted.
set -euo pipefail
cd "$(dirname "$0")/.."
SGM=${SGM:-target/release/sgm}
WORK=$(mktemp -d /tmp/sgm-interop.XXXXXX)
export ROS_MASTER_URI=http://127.0.0.1:11311 ROS_IP=127.0.0.1 ROS_HOME=$WORK/roshome
mkdir -p "$ROS_HOME"
PIDS=()
NETNS=()
cleanup() {
  for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${PIDS[@]}"; do wait "$pid" 2>/dev/null || true; done
  for ns in "${NETNS[@]}"; do ip netns del "$ns" 2>/dev/null || true; done
}
trap cleanup EXIT
fail() { echo "ros interop FAILED: $*" >&2; exit 1; }

echo "== bags written by sgm run, checked by rosbag"
"$SGM" run quickstart --quiet --out "$WORK/run" --bag-out "$WORK/bags" >/dev/null
for robot in alpha bravo; do
  rosbag info "$WORK/bags/$robot.bag" > "$WORK/$robot.info" || fail "rosbag info $robot.bag"
  grep "sensor_msgs/PointCloud2" "$WORK/$robot.info" >/dev/null || fail "rosbag info $robot.bag: no PointCloud2"
  rosbag check "$WORK/bags/$robot.bag" >/dev/null || fail "rosbag check $robot.bag"
done

echo "== the shipped ROS package: one roslaunch per robot, inputs remapped, through rosmaster"
# The team's own key, made as the book's security chapter says (the built-in one is refused).
(umask 077 && head -c 32 /dev/urandom | od -An -vtx1 | tr -d ' \n' > "$WORK/team.key")
[ "$(stat -c %a "$WORK/team.key")" = 600 ] && grep -xE '[0-9a-f]{64}' "$WORK/team.key" >/dev/null \
  || fail "team.key: mode $(stat -c %a "$WORK/team.key"), $(wc -c < "$WORK/team.key") bytes"
# As the book's step by step: the package on ROS_PACKAGE_PATH, `sgm` on PATH (where the
# package's scripts/sgm_node finds it; SGM_BIN if the binary has another name).
export ROS_PACKAGE_PATH=$PWD/bridge/ros:${ROS_PACKAGE_PATH:-/usr/share}
SGM_PATH=$(cd "$(dirname "$SGM")" && pwd)
if [ "$(basename "$SGM")" = sgm ]; then SGM_PATH="$SGM_PATH:$PATH"; else export SGM_BIN="$SGM_PATH/$(basename "$SGM")"; SGM_PATH=$PATH; fi
# roslaunch's own check (roslaunch-check's): the files parse, the package and sgm_node are found.
/usr/bin/python3 - bridge/ros/sgm/launch/two_robots.launch <<'PY' || fail "roslaunch check of two_robots.launch"
import sys, roslaunch.rlutil
error = roslaunch.rlutil.check_roslaunch(sys.argv[1])
assert error is None, error
PY
[ "$(roslaunch --nodes sgm two_robots.launch | tr '\n' ' ')" = "/alpha/sgm_alpha /bravo/sgm_bravo " ] \
  || fail "roslaunch --nodes sgm two_robots.launch: $(roslaunch --nodes sgm two_robots.launch 2>&1)"
ss -ltn | grep ':11311 ' >/dev/null && fail "port 11311 busy"
rosmaster --core -p 11311 >"$ROS_HOME/master.log" 2>&1 & PIDS+=($!)
for _ in $(seq 100); do rostopic list >/dev/null 2>&1 && break; sleep 0.1; done
# Each robot as on its own computer: robot.launch with its LiDAR and odometry on the names a
# Velodyne driver and FAST-LIO use (the bags' topics are renamed to match by rosbag play below).
# One after the other: two roslaunch starting at once on a fresh master race on /run_id.
LAUNCH_STARTED=$(date +%s.%N)
launch_robot() {
  PATH="$SGM_PATH" roslaunch sgm robot.launch robot:="$1" id:="$2" team_key_file:="$WORK/team.key" \
    points:=velodyne_points odometry:=Odometry \
    >"$WORK/roslaunch_$1.log" 2>&1 &
  LAUNCHED=$!; PIDS+=($LAUNCHED)
  for _ in $(seq 100); do rosnode list 2>/dev/null | grep "^/$1/sgm_$1\$" >/dev/null && return 0; sleep 0.2; done
  cat "$WORK/roslaunch_$1.log"; fail "roslaunch of $1: no node /$1/sgm_$1"
}
launch_robot alpha 1; LAUNCH_A=$LAUNCHED
launch_robot bravo 2; LAUNCH_B=$LAUNCHED
[ "$(rosnode list 2>/dev/null | tr '\n' ' ')" = "/alpha/sgm_alpha /bravo/sgm_bravo " ] \
  || { cat "$WORK"/roslaunch_*.log; fail "roslaunch: the nodes are not /alpha/sgm_alpha and /bravo/sgm_bravo: $(rosnode list 2>&1)"; }
# children PID: the processes whose parent is PID (sgm_node execs sgm, so: the node).
children() {
  local stat line fields
  for stat in /proc/[0-9]*/stat; do
    { read -r line < "$stat"; } 2>/dev/null || continue
    read -r -a fields <<< "${line##*) }"   # after "PID (COMM) ": state, parent PID, …
    [ "${fields[1]}" = "$1" ] && echo "${stat//[!0-9]/}"
  done
  return 0
}
ALPHA=$(children "$LAUNCH_A") BRAVO=$(children "$LAUNCH_B")
[ -n "$ALPHA" ] && [ -n "$BRAVO" ] && kill -0 $ALPHA $BRAVO || fail "roslaunch's nodes not found: '$ALPHA' '$BRAVO'"
echo "  roslaunch: /alpha/sgm_alpha (pid $ALPHA) and /bravo/sgm_bravo (pid $BRAVO) up in" \
  "$(/usr/bin/python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$LAUNCH_STARTED" "$(date +%s.%N)") s"
rosbag record -q --lz4 -O "$WORK/recorded.bag" /alpha/velodyne_points /alpha/labels /alpha/camera_info /alpha/Odometry \
  /bravo/velodyne_points /bravo/labels /bravo/camera_info /bravo/Odometry /tf_static >/dev/null 2>&1 & RECORD=$!; PIDS+=($RECORD)
sleep 1
# One rosbag play per robot, as each robot's own recording would be played: a latched topic
# keeps only a publisher's last message, and one player of both bags publishes both robots'
# /tf_static mounts on one publisher, so a subscriber that connects after the second has only it.
rosbag play -q -r 3 "$WORK/bags/alpha.bag" \
  /alpha/points:=/alpha/velodyne_points /alpha/odometry:=/alpha/Odometry >/dev/null 2>&1 & PLAY_ALPHA=$!
rosbag play -q -r 3 "$WORK/bags/bravo.bag" \
  /bravo/points:=/bravo/velodyne_points /bravo/odometry:=/bravo/Odometry >/dev/null 2>&1
wait "$PLAY_ALPHA"
sleep 3
kill -INT "$RECORD"; wait "$RECORD" 2>/dev/null || true

# status ROBOT [COMMAND PREFIX]: the robot's latest status JSON.
status() { "${@:2}" timeout 20 rostopic echo -n 1 "/$1/sgm/status" | /usr/bin/python3 -c '
import sys, json, yaml
doc = yaml.safe_load(sys.stdin.read().split("---")[0])
print(doc["data"])'; }
# settled_status ROBOT FILE [COMMAND PREFIX]: the status into FILE once every accepted cloud is
# assembled into a frame (or after 30 s): a loaded machine may still be working through the last.
settled_status() {
  for _ in $(seq 30); do
    status "$1" "${@:3}" > "$2" || return 1
    /usr/bin/python3 -c 'import json, sys; s = json.load(open(sys.argv[1])); sys.exit(s["sync"]["frames"] < s["accepted"]["points"])' "$2" \
      && return 0
    sleep 1
  done
}
# check_run ROBOT FILE: every frame accepted and assembled, nothing refused, aligned.
check_run() {
  /usr/bin/python3 - "$2" "$1" <<'PY' || fail "$1 status"
import json, sys
s = json.load(open(sys.argv[1]))
assert s["accepted"]["points"] == 180, s["accepted"]
assert s["sync"]["frames"] == 180, s["sync"]
assert all(v == 0 for v in s["refused"].values()), s["refused"]
assert s["neighbours"] and all(n["state"] == "Aligned" for n in s["neighbours"]), s["neighbours"]
assert s["transport"]["sent"] > 0 and s["transport"]["received"] > 0, s["transport"]
inter = s["pose_graph"]["inter_robot"]
assert inter and all(p["factors"] > 0 and p["inconsistent"] == 0 for p in inter), s["pose_graph"]
assert all(n["suspect"] == [] for n in s["neighbours"]), [n["suspect"] for n in s["neighbours"]]
print(f"  {sys.argv[2]}: 180/180 frames, {s['keyframes']} keyframes, {s['objects']} objects, aligned at "
      + ", ".join(f"{n['first_aligned'] - 1700000000:.0f} s" for n in s["neighbours"])
      + ", inter-robot factors " + ", ".join(f"{p['factors']} ({n['closures']['rounds']} closure rounds)" for p, n in zip(inter, s["neighbours"]))
      + f"; {s['transport']['sent']} envelopes sent, {s['transport']['received']} received")
PY
}
for robot in alpha bravo; do
  settled_status "$robot" "$WORK/$robot.status.json" || fail "$robot's status"
  check_run "$robot" "$WORK/$robot.status.json"
done
# The book's checks: the delivery services, and the status as JSON through `rostopic echo -p`.
rosservice list > "$WORK/services.txt" || fail "rosservice list"
grep -x /sgm/robot_1/deliver "$WORK/services.txt" >/dev/null && grep -x /sgm/robot_2/deliver "$WORK/services.txt" >/dev/null \
  || fail "delivery services: $(cat "$WORK/services.txt")"
timeout 20 rostopic echo -n 1 -p /alpha/sgm/status | tail -n 1 | cut -d, -f2- | /usr/bin/python3 -m json.tool \
  > "$WORK/alpha.status.pretty" || fail "the book's status command"
grep '"robot": "alpha"' "$WORK/alpha.status.pretty" >/dev/null || fail "the book's status command: no robot alpha"
# Whole outputs to files, then grep: grep -q in a pipe would close it early (SIGPIPE + pipefail).
timeout 20 rostopic echo -n 1 /alpha/sgm/markers > "$WORK/markers.txt" || fail "rostopic echo markers"
grep 'ns: "objects"' "$WORK/markers.txt" >/dev/null || fail "no object markers"
grep 'type: 9' "$WORK/markers.txt" >/dev/null || fail "no text labels"
timeout 20 rostopic echo -n 1 /bravo/sgm/path/poses[0]/header/frame_id > "$WORK/path.txt" || fail "rostopic echo path"
grep 'bravo/odom' "$WORK/path.txt" >/dev/null || fail "path frame"

echo "== malformed messages are refused and counted"
rostopic pub -1 /alpha/labels sensor_msgs/Image \
  "{header: {frame_id: alpha/camera}, width: 2, height: 1, encoding: yuv422, step: 4, data: [1,2,3,4]}" >/dev/null
rostopic pub -1 /alpha/velodyne_points sensor_msgs/PointCloud2 \
  "{header: {frame_id: elsewhere}, width: 1, height: 1, point_step: 12, row_step: 12}" >/dev/null
rostopic pub -1 /alpha/Odometry nav_msgs/Odometry \
  "{header: {frame_id: alpha/odom}, child_frame_id: alpha/base_link, pose: {pose: {orientation: {w: 0.0}}}}" >/dev/null
sleep 2
kill -0 "$ALPHA" || fail "alpha died on malformed input"
status alpha > "$WORK/alpha.status2.json"
/usr/bin/python3 - "$WORK/alpha.status2.json" <<'PY' || fail "refusals not counted"
import json, sys
s = json.load(open(sys.argv[1]))
assert s["refused"] == {"camera_info": 0, "clock": 0, "labels": 1, "odometry": 1, "points": 1, "tf": 0, "tf_static": 0}, \
    s["refused"]
print("  alpha refused", s["refused"], "and kept running")
PY
# Ctrl-C on roslaunch stops its node (SIGINT) and roslaunch exits 0.
for launch in "$LAUNCH_A" "$LAUNCH_B"; do
  kill -INT "$launch"
  rc=0; wait "$launch" || rc=$?
  [ "$rc" = 0 ] || { cat "$WORK"/roslaunch_*.log; fail "roslaunch exited with $rc"; }
done
for pid in $ALPHA $BRAVO; do kill -0 "$pid" 2>/dev/null && fail "node $pid still runs after roslaunch stopped"; done
KEEP=(); for pid in "${PIDS[@]}"; do [ "$pid" = "$LAUNCH_A" ] || [ "$pid" = "$LAUNCH_B" ] || KEEP+=("$pid"); done
PIDS=("${KEEP[@]}")
echo "  SIGINT to each roslaunch stopped its node"

echo "== a bag recorded by Debian's rosbag replays through sgm replay"
rosbag info "$WORK/recorded.bag" > "$WORK/recorded.info" || fail "rosbag info recorded.bag"
grep lz4 "$WORK/recorded.info" >/dev/null || fail "recorded bag not lz4"
# One bag holds both robots: each reads its own namespace's topics (as renamed above).
SGM__ROS__TOPICS__POINTS='/{robot}/velodyne_points' SGM__ROS__TOPICS__LABELS='/{robot}/labels' \
SGM__ROS__TOPICS__CAMERA_INFO='/{robot}/camera_info' SGM__ROS__TOPICS__ODOMETRY='/{robot}/Odometry' \
  "$SGM" replay --bag "$WORK/recorded.bag" --bag "$WORK/recorded.bag" --config quickstart \
  --out "$WORK/replay" --quiet > "$WORK/replay.txt" || fail "sgm replay"
cat "$WORK/replay.txt"
[ "$(grep -c "Aligned" "$WORK/replay.txt")" = 2 ] || fail "replayed robots did not align"
if [ "$(id -u)" = 0 ] && command -v ip >/dev/null; then
  echo "== two robots in their own network namespaces, joined by veth, fed by rospy"
  for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${PIDS[@]}"; do wait "$pid" 2>/dev/null || true; done
  PIDS=()
  A=sgm_a_$$ B=sgm_b_$$ VA=sgmva$$ VB=sgmvb$$
  ip netns add "$A" && NETNS+=("$A") && ip netns add "$B" && NETNS+=("$B") || fail "ip netns add"
  ip link add "$VA" type veth peer name "$VB" || fail "ip link add veth"
  ip link set "$VA" netns "$A" && ip link set "$VB" netns "$B"
  ip -n "$A" addr add 10.231.0.1/24 dev "$VA" && ip -n "$B" addr add 10.231.0.2/24 dev "$VB"
  for ns in "$A:$VA" "$B:$VB"; do ip -n "${ns%%:*}" link set lo up; ip -n "${ns%%:*}" link set "${ns#*:}" up; done
  export ROS_MASTER_URI=http://10.231.0.1:11311
  in_a() { ROS_IP=10.231.0.1 ip netns exec "$A" "$@"; }
  in_b() { ROS_IP=10.231.0.2 ip netns exec "$B" "$@"; }
  # For `&`: a function runs in a subshell there, so exec, or $! is the subshell and stopping it
  # would leave the process running in the namespace.
  bg_a() { ROS_IP=10.231.0.1 exec ip netns exec "$A" "$@"; }
  bg_b() { ROS_IP=10.231.0.2 exec ip netns exec "$B" "$@"; }
  bg_a rosmaster --core -p 11311 >"$ROS_HOME/master_netns.log" 2>&1 & PIDS+=($!)
  for _ in $(seq 100); do in_b rostopic list >/dev/null 2>&1 && break; sleep 0.1; done
  in_b rostopic list >/dev/null 2>&1 || fail "the master in $A is not reachable from $B"
  SGM__COMMS__TEAM_KEY_FILE=$WORK/team.key bg_a "$SGM" ros --robot alpha --scenario quickstart __ns:=/alpha \
    >"$WORK/alpha_netns.log" 2>&1 & PIDS+=($!)
  SGM__COMMS__TEAM_KEY_FILE=$WORK/team.key bg_b "$SGM" ros --robot bravo --scenario quickstart __ns:=/bravo \
    >"$WORK/bravo_netns.log" 2>&1 & PIDS+=($!)
  bg_a /usr/bin/python3 tests/ros_feed.py "$WORK/bags/alpha.bag" 3 >"$WORK/feed_alpha.log" 2>&1 & FEED_A=$!; PIDS+=($FEED_A)
  bg_b /usr/bin/python3 tests/ros_feed.py "$WORK/bags/bravo.bag" 3 >"$WORK/feed_bravo.log" 2>&1 & FEED_B=$!; PIDS+=($FEED_B)
  wait "$FEED_A" || { cat "$WORK/feed_alpha.log"; fail "rospy feeder of alpha"; }
  wait "$FEED_B" || { cat "$WORK/feed_bravo.log"; fail "rospy feeder of bravo"; }
  sleep 3
  # alpha's status read in B and bravo's in A: the topic crosses the veth either way.
  settled_status alpha "$WORK/alpha.netns.json" in_b || fail "alpha's status from $B"
  check_run alpha "$WORK/alpha.netns.json"
  settled_status bravo "$WORK/bravo.netns.json" in_a || fail "bravo's status from $A"
  check_run bravo "$WORK/bravo.netns.json"
  ip -n "$A" -s -j link show "$VA" > "$WORK/veth.json"
  /usr/bin/python3 - "$WORK/veth.json" <<'PY' || fail "no traffic on the veth"
import json, sys
stats = json.load(open(sys.argv[1]))[0]["stats64"]
tx, rx = stats["tx"]["bytes"], stats["rx"]["bytes"]
assert tx > 100_000 and rx > 100_000, stats
print(f"  veth between the namespaces: {tx / 1e6:.1f} MB out of A, {rx / 1e6:.1f} MB into A")
PY
else
  echo "== (not root: the network-namespace test is skipped)"
fi
echo "ros interop: all passed ($WORK)"
