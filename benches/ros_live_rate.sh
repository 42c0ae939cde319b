#!/usr/bin/env bash
# Live rate of `sgm ros` (issue "field-ros"): the robots of SCENARIO (default outdoor_two_robots,
# 10 minutes) with their sensors at RATE_HZ (default 10 Hz clouds and 10 Hz label images), each
# an `sgm ros` process under one rosmaster on 127.0.0.1, fed by `rosbag play` at 1× (real time).
# At the end: per robot, clouds in the bag, clouds the node received and frames it assembled
# (none may be lost for lack of CPU), latency per frame from handed to the robot to handled by
# its Tracker (p50/p95/p99/max), CPU time and peak memory. Needs Debian's ros-core and a release
# build: `cargo build --release --bin sgm`. Takes the scenario's duration plus the time to
# write its bags (several GB in WORK, default /tmp).
set -euo pipefail
cd "$(dirname "$0")/.."
SGM=${SGM:-target/release/sgm}
SCENARIO=${SCENARIO:-outdoor_two_robots}
RATE_HZ=${RATE_HZ:-10}
WORK=$(mktemp -d "${WORK_DIR:-/tmp}/sgm-live.XXXXXX")
PY=/usr/bin/python3
export ROS_MASTER_URI=http://127.0.0.1:11331 ROS_IP=127.0.0.1 ROS_HOME=$WORK/roshome
mkdir -p "$ROS_HOME"
PIDS=()
cleanup() {
  for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${PIDS[@]}"; do wait "$pid" 2>/dev/null || true; done
  [ "${LIVE_KEEP:-0}" = 1 ] && echo "kept $WORK" || rm -rf "$WORK"
}
trap cleanup EXIT
fail() { echo "live rate FAILED: $*" >&2; exit 1; }
interval=$($PY -c "print(1 / float('$RATE_HZ'))")
echo "== $SCENARIO at $RATE_HZ Hz: bags"
SGM__SCENARIO__FRAME_INTERVAL_S=$interval "$SGM" run "$SCENARIO" --quiet --out "$WORK/sim" --bag-out "$WORK/bags" \
  > "$WORK/sim.txt" || fail "sgm run"
ROBOTS=()
for bag in "$WORK"/bags/*.bag; do ROBOTS+=("$(basename "$bag" .bag)"); done
du -sh "$WORK/bags"
(umask 077 && head -c 32 /dev/urandom | od -An -vtx1 | tr -d ' \n' > "$WORK/team.key")
ss -ltn | grep -q ':11331 ' && fail "port 11331 busy"
rosmaster --core -p 11331 >"$WORK/master.log" 2>&1 & PIDS+=($!)
for _ in $(seq 100); do rosnode list >/dev/null 2>&1 && break; sleep 0.1; done
declare -A NODE
for r in "${ROBOTS[@]}"; do
  SGM__COMMS__TEAM_KEY_FILE=$WORK/team.key NO_COLOR=1 /usr/bin/time -v -o "$WORK/$r.time" \
    "$SGM" ros --robot "$r" --scenario "$SCENARIO" "__ns:=/$r" >"$WORK/$r.log" 2>&1 & NODE[$r]=$!; PIDS+=($!)
done
for r in "${ROBOTS[@]}"; do
  for _ in $(seq 100); do rosnode list 2>/dev/null | grep -x "/$r/sgm_$r" >/dev/null && break; sleep 0.2; done
done
plays=()
for r in "${ROBOTS[@]}"; do
  rosbag play -q --wait-for-subscribers "$WORK/bags/$r.bag" \
    --topics "/$r/points" "/$r/labels" "/$r/camera_info" "/$r/odometry" >"$WORK/play_$r.log" 2>&1 & plays+=($!); PIDS+=($!)
done
started=$SECONDS
for p in "${plays[@]}"; do wait "$p" || fail "rosbag play"; done
echo "  played in $(( SECONDS - started )) s"
sleep 5
for r in "${ROBOTS[@]}"; do
  timeout 20 rostopic echo -n 1 "/$r/sgm/status" | $PY -c '
import sys, yaml
print(yaml.safe_load(sys.stdin.read().split("---")[0])["data"])' > "$WORK/$r.json"
  rosbag info --yaml --key=topics "$WORK/bags/$r.bag" | $PY -c '
import sys, yaml
print(next(t["messages"] for t in yaml.safe_load(sys.stdin) if t["topic"].endswith("/points")))' > "$WORK/$r.clouds"
  pkill -INT -P "${NODE[$r]}"   # the node under /usr/bin/time (time ignores SIGINT)
done
for r in "${ROBOTS[@]}"; do wait "${NODE[$r]}" || true; done
$PY - "$WORK" "${ROBOTS[@]}" <<'PY'
import json, re, sys
work, robots = sys.argv[1], sys.argv[2:]
bad = False
for r in robots:
    s = json.load(open(f"{work}/{r}.json"))
    clouds = int(open(f"{work}/{r}.clouds").read())
    t = open(f"{work}/{r}.time").read()
    cpu = sum(float(re.search(rf"{k} time \(seconds\): ([\d.]+)", t).group(1)) for k in ("User", "System"))
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
    l = s["latency_ms"]
    print(f"  {r}: {clouds} clouds in the bag, {s['accepted']['points']} received, {s['sync']['frames']} frames; "
          f"latency p50 {l['p50_ms']:.1f} ms, p95 {l['p95_ms']:.1f}, p99 {l['p99_ms']:.1f}, max {l['max_ms']:.1f} "
          f"over {l['frames']} frames; CPU {cpu:.0f} s, peak {rss:.0f} MiB; aligned with "
          + ", ".join(str(n["robot"]) for n in s["neighbours"] if n["state"] == "Aligned"))
    bad |= s["accepted"]["points"] != clouds or s["sync"]["frames"] != clouds
sys.exit(1 if bad else 0)
PY
echo "live rate: no frame lost"
