# Shared by the ROS test scripts that source it (tests/ros_fast_lio.sh, tests/ros_rviz.sh),
# after `set -euo pipefail` and a `cd` to the repository root:
#   ros_script NAME   a work directory /tmp/sgm-NAME.XXXXXX ($WORK), a ROS environment on
#                     127.0.0.1 ($ROS_HOME in it), PIDS stopped (TERM, then waited for) at exit,
#                     `fail` naming the script, $SGM (default target/release/sgm), the ROS
#                     package on ROS_PACKAGE_PATH and $SGM_PATH: a PATH on which roslaunch's
#                     sgm_node finds $SGM (or SGM_BIN set);
#   start_master      rosmaster --core on 127.0.0.1:$ROS_PORT (refused if the port is busy);
#                     ROS_PORT is SGM_ROS_PORT, default 11311 (.ci/run gives a script that runs
#                     beside another one a port of its own);
#   team_key          a team key as the book makes it, in $WORK/team.key.
# and, without ros_script (the scripts that only want these source this file before they
# define their own `fail`):
#   short_quickstart SECONDS FILE   scenarios/library/quickstart.toml cut to SECONDS of mission,
#                     written to FILE (fails if the file no longer says duration_s = 90.0);
#   bag_messages BAG TOPIC          how many messages BAG holds on TOPIC (rosbag info).
ros_script() {
  SCRIPT_NAME=$1
  SGM=${SGM:-target/release/sgm}
  WORK=$(mktemp -d "/tmp/sgm-$1.XXXXXX")
  ROS_PORT=${SGM_ROS_PORT:-11311}
  export ROS_MASTER_URI=http://127.0.0.1:$ROS_PORT ROS_IP=127.0.0.1 ROS_HOME=$WORK/roshome
  mkdir -p "$ROS_HOME"
  PIDS=()
  trap ros_script_cleanup EXIT
  export ROS_PACKAGE_PATH=$PWD/bridge/ros:${ROS_PACKAGE_PATH:-/usr/share}
  SGM_PATH=$(cd "$(dirname "$SGM")" && pwd)
  if [ "$(basename "$SGM")" = sgm ]; then
    SGM_PATH="$SGM_PATH:$PATH"
  else
    export SGM_BIN="$SGM_PATH/$(basename "$SGM")"
    SGM_PATH=$PATH
  fi
}

ros_script_cleanup() {
  for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${PIDS[@]}"; do wait "$pid" 2>/dev/null || true; done
}

fail() { echo "$SCRIPT_NAME FAILED: $*" >&2; exit 1; }

start_master() {
  ss -ltn | grep ":$ROS_PORT " >/dev/null && fail "port $ROS_PORT busy"
  rosmaster --core -p "$ROS_PORT" >"$ROS_HOME/master.log" 2>&1 & PIDS+=($!)
  for _ in $(seq 100); do rostopic list >/dev/null 2>&1 && return 0; sleep 0.1; done
  fail "rosmaster did not start"
}

team_key() {
  (umask 077 && head -c 32 /dev/urandom | od -An -vtx1 | tr -d ' \n' > "$WORK/team.key")
}

short_quickstart() {
  sed "s/^duration_s = 90.0$/duration_s = $1/" scenarios/library/quickstart.toml >"$2"
  grep -q "^duration_s = $1$" "$2" || { echo "quickstart.toml has no duration_s = 90.0 to shorten" >&2; return 1; }
}

bag_messages() {
  rosbag info --yaml --key=topics "$1" | /usr/bin/python3 -c '
import sys, yaml
print(next(t["messages"] for t in yaml.safe_load(sys.stdin) if t["topic"] == sys.argv[1]))' "$2"
}
