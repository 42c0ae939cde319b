#!/usr/bin/env bash
# RViz on what SGM publishes, as the book's "Deploy on your robots" chapter shows it: Debian's
# RViz under Xvfb with the ROS package's rviz/team.rviz,
#   1. against two running `sgm ros` nodes (roslaunch sgm two_robots.launch) fed quickstart's
#      bags by `rosbag play`: once both align, a screenshot shows each class colour of the
#      quickstart world's objects (tree, lamp post, bench, trash can) in at least 100 pixels;
#   2. on a run's result bag (`sgm run quickstart` writes result.bag) played by `rosbag play`
#      with no node running: the same colours, and `rosbag check` accepts the bag.
# SGM_RVIZ_SHOTS=DIR keeps the two screenshots (PNG) there. Needs `sgm` (SGM=…), Debian's ROS 1
# packages and rviz, xvfb, imagemagick, libgl1-mesa-dri (.ci/run installs them). Everything
# listens on 127.0.0.1; every process started here is stopped by PID.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=tests/ros_common.sh
. tests/ros_common.sh
ros_script ros_rviz
stop() { kill -TERM "$1" 2>/dev/null || true; wait "$1" 2>/dev/null || true; }

"$SGM" run quickstart --quiet --out "$WORK/run" --bag-out "$WORK/bags" >/dev/null
rosbag check "$WORK/run/result.bag" >/dev/null || fail "rosbag check result.bag"
team_key
RVIZ_CONFIG=$PWD/bridge/ros/sgm/rviz/team.rviz
[ -f "$RVIZ_CONFIG" ] || fail "no $RVIZ_CONFIG"

# A free X display for Xvfb.
DISPLAY_N=
for n in $(seq 90 120); do [ -e "/tmp/.X$n-lock" ] || [ -e "/tmp/.X11-unix/X$n" ] || { DISPLAY_N=$n; break; }; done
[ -n "$DISPLAY_N" ] || fail "no free X display"
Xvfb ":$DISPLAY_N" -screen 0 1280x800x24 -nolisten tcp >"$WORK/xvfb.log" 2>&1 & PIDS+=($!)
export DISPLAY=":$DISPLAY_N" LIBGL_ALWAYS_SOFTWARE=1
for _ in $(seq 50); do [ -e "/tmp/.X11-unix/X$DISPLAY_N" ] && break; sleep 0.1; done

start_master

# start_rviz: RViz on the package's configuration (before the data: markers are not latched).
start_rviz() {
  rviz -d "$RVIZ_CONFIG" >"$WORK/rviz_$1.log" 2>&1 & RVIZ=$!; PIDS+=($RVIZ)
  for _ in $(seq 100); do rosnode list 2>/dev/null | grep -q '^/rviz' && return 0; sleep 0.2; done
  cat "$WORK/rviz_$1.log"; fail "rviz did not start"
}
# shot NAME: a screenshot of the whole screen; prints pixels per class colour; fails unless each
# of the quickstart world's object classes shows in at least 100 pixels of its exact colour.
shot() {
  sleep 3
  import -window root "$WORK/$1.png" || fail "import (screenshot)"
  /usr/bin/convert "$WORK/$1.png" "$WORK/$1.ppm" || fail "convert to ppm"
  [ -n "${SGM_RVIZ_SHOTS:-}" ] && mkdir -p "$SGM_RVIZ_SHOTS" && cp "$WORK/$1.png" "$SGM_RVIZ_SHOTS/"
  /usr/bin/python3 - "$WORK/$1.ppm" "$1" <<'PY' || fail "$1: class colours missing from the screenshot"
import collections, sys
data = open(sys.argv[1], "rb").read()
magic, size, maxval, pixels = data.split(b"\n", 3)
assert magic == b"P6" and maxval == b"255", (magic, maxval)
counts = collections.Counter(pixels[i:i + 3] for i in range(0, len(pixels), 3))
# fusion.classes' colours (actors/src/config.rs, default_classes) of quickstart's objects.
colours = {"tree": (30, 140, 40), "lamp_post": (250, 220, 60), "bench": (150, 90, 40), "trash_can": (60, 60, 200)}
seen = {name: counts[bytes(rgb)] for name, rgb in colours.items()}
print(f"  {sys.argv[2]}: pixels per class colour {seen} ({size.decode()} screenshot)")
assert all(n >= 100 for n in seen.values()), seen
PY
}

echo "== RViz beside two running nodes"
start_rviz live
PATH="$SGM_PATH" roslaunch sgm two_robots.launch team_key_file:="$WORK/team.key" >"$WORK/roslaunch.log" 2>&1 & LAUNCH=$!; PIDS+=($LAUNCH)
for _ in $(seq 150); do [ "$(rosnode list 2>/dev/null | grep -c sgm_)" = 2 ] && break; sleep 0.2; done
[ "$(rosnode list 2>/dev/null | grep -c sgm_)" = 2 ] || { cat "$WORK/roslaunch.log"; fail "the two nodes did not start"; }
rosbag play -q -r 3 "$WORK/bags/alpha.bag" "$WORK/bags/bravo.bag" --topics /alpha/points /alpha/labels \
  /alpha/camera_info /alpha/odometry /bravo/points /bravo/labels /bravo/camera_info /bravo/odometry /tf_static \
  >/dev/null 2>&1 || fail "rosbag play"
aligned() { timeout 20 rostopic echo -n 1 "/$1/sgm/status" | /usr/bin/python3 -c '
import sys, yaml, json
s = json.loads(yaml.safe_load(sys.stdin.read().split("---")[0])["data"])
sys.exit(0 if s["neighbours"] and all(n["state"] == "Aligned" for n in s["neighbours"]) else 1)'; }
aligned alpha && aligned bravo || fail "the nodes did not align"
shot live
stop "$RVIZ"; stop "$LAUNCH"

echo "== RViz on a run's result bag, no node running"
start_rviz result
rosbag play -q -r 10 "$WORK/run/result.bag" >/dev/null 2>&1 || fail "rosbag play result.bag"
shot result
echo "ros rviz: all checks passed"
