#!/usr/bin/env bash
# A fleet whose odometry is FAST-LIO, as the book's "Deploy on your robots" chapter sets it up:
# FAST-LIO publishes /Odometry, /cloud_registered_body and tf camera_init -> body under the same
# absolute names and frames on every robot. Against Debian's rosmaster and roslaunch, two robots
# started by `roslaunch sgm fast_lio_robot.launch` (the shipped launch file and
# config/fast_lio.toml, as they are), each with a stand-in for FAST-LIO's node (package
# tests/ros_packages/fast_lio: the same names, fed from quickstart's bags):
#   1. roslaunch's own check of the launch file; `roslaunch --nodes` names /alpha/laserMapping
#      and /alpha/sgm_alpha;
#   2. FAST-LIO's names land in each robot's namespace: /alpha/Odometry, /alpha/tf, its inputs
#      /alpha/livox/lidar; nothing on the global /Odometry or /cloud_registered_body;
#   3. both robots take every frame (nothing refused), align, read the camera's mount from their
#      own tf_static under FAST-LIO's body (renamed alpha/base_link), find the odometry and
#      FAST-LIO's tf in agreement, and raise no health finding;
#   4. on the global /tf: each robot's body under its own world (alpha/odom -> alpha/base_link)
#      and the team's tree (alpha/odom -> bravo/odom);
#   5. `sgm doctor --live` with the launch file's remappings says OK for every input; without
#      them it fails on points, naming the PointCloud2 topics the master has.
# Needs `sgm` (SGM=…) and Debian's ROS 1 packages (.ci/run installs them). Everything listens on
# 127.0.0.1; every process started here is stopped by PID.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=tests/ros_common.sh
. tests/ros_common.sh
ros_script ros_fast_lio
# A failure shows the tail of each robot's roslaunch output.
fail() {
  echo "ros fast_lio FAILED: $*" >&2
  for f in "$WORK"/roslaunch_*.log; do [ -e "$f" ] && tail -n 30 "$f" >&2; done
  exit 1
}
export ROS_PACKAGE_PATH=$ROS_PACKAGE_PATH:$PWD/tests/ros_packages
# The simulated camera speaks ADE20K-150 ids, as the segmenter config/fast_lio.toml names.
SGM__CLASSES__SEGMENTER=ade20k_150 "$SGM" run quickstart --quiet --out "$WORK/run" --bag-out "$WORK/bags" >/dev/null
team_key
export FAST_LIO_STUB_BAGS=$WORK/bags FAST_LIO_STUB_RATE=${FAST_LIO_STUB_RATE:-3}

echo "== fast_lio_robot.launch: roslaunch's check, its nodes"
/usr/bin/python3 - bridge/ros/sgm/launch/fast_lio_robot.launch <<'PY' || fail "roslaunch check of fast_lio_robot.launch"
import sys, roslaunch.rlutil
error = roslaunch.rlutil.check_roslaunch(sys.argv[1], ignore_unset_args=True)  # robot:=, id:= are the user's
assert error is None, error
PY
NODES=$(roslaunch --nodes sgm fast_lio_robot.launch robot:=alpha id:=1 | tr '\n' ' ')
[ "$NODES" = "/alpha/laserMapping /alpha/sgm_alpha " ] || fail "roslaunch --nodes: $NODES"

start_master
# The global /tf as RViz would see it: every (parent, child) pair, recorded while the robots run.
/usr/bin/python3 - "$WORK/tf_pairs.txt" <<'PY' & PIDS+=($!)
import sys, rospy
from tf2_msgs.msg import TFMessage
pairs = set()
def heard(m):
    for t in m.transforms:
        pair = f"{t.header.frame_id} {t.child_frame_id}"
        if pair not in pairs:
            pairs.add(pair)
            with open(sys.argv[1], "a") as f:
                f.write(pair + "\n")
rospy.init_node("tf_pairs", anonymous=True)
rospy.Subscriber("/tf", TFMessage, heard)
rospy.spin()
PY
echo "== two robots, each: roslaunch sgm fast_lio_robot.launch robot:=NAME id:=ID"
launch_robot() {
  PATH="$SGM_PATH" roslaunch sgm fast_lio_robot.launch robot:="$1" id:="$2" team_key_file:="$WORK/team.key" \
    >"$WORK/roslaunch_$1.log" 2>&1 & PIDS+=($!)
  for _ in $(seq 100); do rosnode list 2>/dev/null | grep "^/$1/sgm_$1\$" >/dev/null && return 0; sleep 0.2; done
  fail "roslaunch of $1: no node /$1/sgm_$1"
}
launch_robot alpha 1
launch_robot bravo 2
# While the stand-ins play (90 s at 3x):
for _ in $(seq 100); do rostopic list 2>/dev/null | grep -x /bravo/Odometry >/dev/null && break; sleep 0.2; done
echo "== FAST-LIO's names in each robot's namespace"
rostopic list > "$WORK/topics.txt"
for t in /alpha/Odometry /bravo/Odometry /alpha/cloud_registered_body /alpha/tf /bravo/tf /alpha/tf_static; do
  grep -x "$t" "$WORK/topics.txt" >/dev/null || fail "no topic $t: $(tr '\n' ' ' < "$WORK/topics.txt")"
done
for t in /Odometry /cloud_registered_body /cloud_registered; do
  grep -x "$t" "$WORK/topics.txt" >/dev/null && fail "FAST-LIO's $t is global"
done
rostopic info /alpha/livox/lidar > "$WORK/lidar.txt"
grep -q "/alpha/laserMapping" "$WORK/lidar.txt" || fail "FAST-LIO does not read /alpha/livox/lidar: $(cat "$WORK/lidar.txt")"

echo "== sgm doctor --live, as the deploy chapter runs it, while the robots run"
# With the launch file's remappings: every input OK. Without them: no publisher on points.
"$SGM" doctor --live --robot alpha --id 1 --config bridge/ros/sgm/config/fast_lio.toml --duration 6 \
  points:=cloud_registered_body odometry:=Odometry > "$WORK/doctor_alpha.txt" || { cat "$WORK/doctor_alpha.txt"; fail "sgm doctor --live alpha"; }
cat "$WORK/doctor_alpha.txt"
grep -q "^verdict: OK" "$WORK/doctor_alpha.txt" || fail "sgm doctor --live alpha: not OK"
rc=0; "$SGM" doctor --live --robot bravo --id 2 --config bridge/ros/sgm/config/fast_lio.toml --duration 3 \
  > "$WORK/doctor_bravo.txt" || rc=$?
[ "$rc" = 1 ] && grep -q "nobody publishes it; sensor_msgs/PointCloud2 topics published on the master: .*/bravo/cloud_registered_body" \
  "$WORK/doctor_bravo.txt" || { cat "$WORK/doctor_bravo.txt"; fail "sgm doctor --live without the remappings (exit $rc)"; }
echo "  without points:=cloud_registered_body: $(grep -m1 'nobody publishes' "$WORK/doctor_bravo.txt" | sed 's/^ *//')"
# The stand-ins play the bags (90 s at 3x), then exit; the nodes stay up.
for _ in $(seq 300); do
  grep -q "messages published" "$WORK/roslaunch_alpha.log" && grep -q "messages published" "$WORK/roslaunch_bravo.log" && break
  sleep 0.5
done
grep -q "messages published" "$WORK/roslaunch_bravo.log" || fail "the FAST-LIO stand-ins did not finish"
sleep 3

echo "== every frame taken, aligned, mounts from tf, odometry and tf agree"
status() { timeout 20 rostopic echo -n 1 "/$1/sgm/status" | /usr/bin/python3 -c '
import sys, yaml
print(yaml.safe_load(sys.stdin.read().split("---")[0])["data"])'; }
for robot in alpha bravo; do
  status "$robot" > "$WORK/$robot.status.json" || fail "$robot's status"
  /usr/bin/python3 - "$WORK/$robot.status.json" "$robot" <<'PY' || fail "$robot's status"
import json, sys
s, robot = json.load(open(sys.argv[1])), sys.argv[2]
assert s["accepted"]["points"] == 180 and s["sync"]["frames"] == 180, (s["accepted"], s["sync"])
assert all(v == 0 for v in s["refused"].values()), s["refused"]
assert s["neighbours"] and all(n["state"] == "Aligned" for n in s["neighbours"]), s["neighbours"]
camera = [m for m in s["tf"]["mounts"] if m["sensor"] == "camera"][0]
assert camera["source"] == "tf" and camera["body_frame"] == f"{robot}/base_link", camera
assert s["tf"]["world_frame"] == f"{robot}/odom", s["tf"]
assert s["tf"]["odometry_compared"] > 100 and s["tf"]["odometry_disagreed"] == 0, s["tf"]
assert s["health"] == [], s["health"]
assert s["fusion"]["segmenter"] == "ade20k_150" and s["fusion"]["unknown_label_points"] == 0, s["fusion"]
print(f"  {robot}: 180/180 frames, {s['objects']} objects, aligned at "
      + ", ".join(f"{n['first_aligned'] - 1700000000:.0f} s" for n in s["neighbours"])
      + f"; camera mount from tf ({camera['body_frame']} <- {camera['sensor_frame']}); odometry against "
      + f"FAST-LIO's tf: {s['tf']['odometry_compared']} compared, {s['tf']['odometry_max_m']:.1e} m apart at most")
PY
done

echo "== the global /tf: bodies under their own worlds, the team's tree"
for pair in "alpha/odom alpha/base_link" "bravo/odom bravo/base_link" "alpha/odom bravo/odom"; do
  grep -x "$pair" "$WORK/tf_pairs.txt" >/dev/null || fail "no $pair on /tf: $(tr '\n' ';' < "$WORK/tf_pairs.txt")"
done
grep -E '^(camera_init|body) |^bravo/odom alpha/odom$' "$WORK/tf_pairs.txt" && fail "/tf carries FAST-LIO's frames or a loop"
echo "  /tf: $(tr '\n' ';' < "$WORK/tf_pairs.txt")"
echo "ros fast_lio: all checks passed"
