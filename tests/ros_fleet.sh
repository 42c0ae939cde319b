#!/usr/bin/env bash
# A fleet of processes in the field (issue "field-ros"), with Debian's real ROS 1 tools, as root:
# N robots as N `sgm ros` processes, each in its own network namespace joined to a bridge by a
# veth shaped by `tc netem` (delay and loss both ways), through one rosmaster, each fed by
# `rosbag play` of its own bag (`sgm run SCENARIO --bag-out`) inside its namespace.
#   1. clean: the fleet plays its bags with nothing going wrong; every pair's time to align is
#      taken as the reference;
#   2. faults: the same, while
#      - the last robot (the victim) is `kill -9`ed and, some seconds later, started again: it
#        resumes from its snapshot (`persistence.interval_s` of the scenario);
#      - robot 2's link is cut (its veth down) and restored;
#      - a rogue node (tests/src/bin/sgm_rogue.rs, without the team key) records the team
#        topic, then publishes forged and replayed envelopes, calls every robot's Deliver service
#        with them, and once the victim is down serves the victim's Deliver service itself,
#        never answering.
#      Every other robot must keep exchanging and align with every robot it aligned with in the
#      first half of the clean run, within 2× the clean time (pairs with robot 2, whose link was
#      cut, in any time; later pairs are reported); no frame of theirs may be lost (every cloud of their
#      bags assembled); the keyframe ledgers settle (nothing pending at the end); the victim's
#      snapshot keyframes are all in its final map; everything the rogue sent is refused and
#      counted (MAC or replay window), and its never-answering service was called.
# Figures (time to align, bytes and CPU per robot) go to stdout and $WORK/fleet.json.
#   FLEET_N (4), FLEET_SCENARIO (field/fleet_four), FLEET_RATE (2), FLEET_DELAY_MS (20),
#   FLEET_LOSS_PCT (1), FLEET_PHASES ("clean faults"), SGM, SGM_ROGUE, FLEET_KEEP=1 keeps $WORK.
# Every process started here is stopped by PID; the namespaces and the bridge are deleted.
set -euo pipefail
cd "$(dirname "$0")/.."
SGM=${SGM:-target/release/sgm}
ROGUE=${SGM_ROGUE:-$(dirname "$SGM")/sgm_rogue}
N=${FLEET_N:-4}
SCENARIO=${FLEET_SCENARIO:-field/fleet_four}
RATE=${FLEET_RATE:-2}
DELAY_MS=${FLEET_DELAY_MS:-20}
LOSS_PCT=${FLEET_LOSS_PCT:-1}
PHASES=${FLEET_PHASES:-clean faults}
WORK=$(mktemp -d /tmp/sgm-fleet.XXXXXX)
PY=/usr/bin/python3
PIDS=()
NETNS=()
BRIDGE=sgmbr$$
# shellcheck source=tests/ros_common.sh
. tests/ros_common.sh
fail() { echo "ros fleet FAILED: $*" >&2; exit 1; }
stop_all() {
  for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${PIDS[@]}"; do
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
  done
  PIDS=()
}
cleanup() {
  stop_all
  for ns in "${NETNS[@]}"; do ip netns del "$ns" 2>/dev/null || true; done
  ip link del "$BRIDGE" 2>/dev/null || true
  [ "${FLEET_KEEP:-0}" = 1 ] && echo "kept $WORK" || rm -rf "$WORK"
}
trap cleanup EXIT
[ "$(id -u)" = 0 ] || fail "needs root (network namespaces)"
for tool in rosmaster rosbag rosnode tc ip; do command -v "$tool" >/dev/null || fail "$tool not installed"; done
[ -x "$SGM" ] && [ -x "$ROGUE" ] || fail "build first: cargo build --release --bin sgm -p sgm-tests --bin sgm_rogue"
ROBOTS=()
for k in $(seq "$N"); do ROBOTS+=("r$k"); done
VICTIM=r$N

echo "== $N robots of $SCENARIO: bags"
"$SGM" run "$SCENARIO" --quiet --out "$WORK/sim" --bag-out "$WORK/bags" > "$WORK/sim.txt" || fail "sgm run $SCENARIO"
for r in "${ROBOTS[@]}"; do [ -f "$WORK/bags/$r.bag" ] || fail "$SCENARIO has no robot $r"; done
# Clouds per robot: every one must become a frame (none lost to a dead peer).
for r in "${ROBOTS[@]}"; do
  bag_messages "$WORK/bags/$r.bag" "/$r/points" > "$WORK/$r.clouds" || fail "rosbag info $r.bag"
done
rosbag info --yaml --key=duration "$WORK/bags/r1.bag" > "$WORK/duration"
(umask 077 && head -c 32 /dev/urandom | od -An -vtx1 | tr -d ' \n' > "$WORK/team.key")

# netem needs the kernel's sch_netem; where it is missing (this project's VMs), the links are
# shaped by a token bucket (tbf) at FLEET_RATE_MBIT instead, and the run says so.
if tc qdisc add dev lo root netem delay 1ms 2>/dev/null; then
  tc qdisc del dev lo root; SHAPE="netem delay ${DELAY_MS}ms loss ${LOSS_PCT}%"
else
  SHAPE="tbf rate ${FLEET_RATE_MBIT:-20}mbit burst 64kbit latency 100ms"
  echo "note: this kernel has no netem (sch_netem): links shaped by '$SHAPE' instead, no delay or loss"
fi
echo "$SHAPE" > "$WORK/shape"
echo "== network: a bridge, a namespace per robot and one for the rogue, each link: $SHAPE"
ip link add "$BRIDGE" type bridge && ip addr add 10.213.0.1/24 dev "$BRIDGE" && ip link set "$BRIDGE" up \
  || fail "bridge"
# add_host NAME INDEX: namespace NAME with 10.213.0.INDEX, its veth shaped both ways.
add_host() {
  local ns=sf$$-$1 host=sf$$h$2 peer=sf$$p$2
  ip netns add "$ns" && NETNS+=("$ns")
  ip link add "$host" type veth peer name "$peer"
  ip link set "$peer" netns "$ns"
  ip link set "$host" master "$BRIDGE" && ip link set "$host" up
  ip -n "$ns" addr add "10.213.0.$2/24" dev "$peer"
  ip -n "$ns" link set lo up && ip -n "$ns" link set "$peer" up
  # shellcheck disable=SC2086 # $SHAPE is the qdisc and its parameters, word by word
  tc qdisc add dev "$host" root $SHAPE && ip netns exec "$ns" tc qdisc add dev "$peer" root $SHAPE
}
for k in $(seq "$N"); do add_host "r$k" $((10 + k)) || fail "namespace of r$k"; done
add_host rogue 9 || fail "namespace of the rogue"
ip_of() { [ "$1" = rogue ] && echo 10.213.0.9 || echo "10.213.0.$((10 + ${1#r}))"; }
export ROS_MASTER_URI=http://10.213.0.1:11311 ROS_HOME=$WORK/roshome
mkdir -p "$ROS_HOME"
# bg WHO CMD…: CMD in WHO's namespace (exec, so $! is the process itself).
bg() { local who=$1; shift; ROS_IP=$(ip_of "$who") exec ip netns exec "sf$$-$who" "$@"; }

# start_robot ROBOT RUN: `sgm ros` in its namespace, snapshots in $WORK/snapshots.
start_robot() {
  # Status five times a second: the test reacts to what it says.
  SGM__ROS__PUBLISH_INTERVAL_S=0.2 SGM__COMMS__TEAM_KEY_FILE=$WORK/team.key \
    SGM__PERSISTENCE__DIRECTORY=$WORK/snapshots RUST_LOG=${FLEET_LOG:-info} NO_COLOR=1 \
    bg "$1" "$SGM" ros --robot "$1" --scenario "$SCENARIO" "__ns:=/$1" >"$WORK/$1.$2.log" 2>&1 &
  STARTED=$!; PIDS+=("$STARTED")
  for _ in $(seq 150); do rosnode list 2>/dev/null | grep -x "/$1/sgm_$1" >/dev/null && return 0; sleep 0.2; done
  cat "$WORK/$1.$2.log"; fail "$1 did not come up"
}
cpu_s() { awk '{ printf "%.2f\n", ($14 + $15) / 100 }' "/proc/$1/stat" 2>/dev/null || echo 0; }

# phase NAME: one run of the fleet; statuses in $WORK/NAME/.
phase() {
  local name=$1 out=$WORK/$1
  mkdir -p "$out"
  rm -rf "$WORK/snapshots"
  ss -ltn | grep -q '10.213.0.1:11311 ' && fail "port 11311 busy on the bridge"
  ROS_IP=10.213.0.1 rosmaster --core -p 11311 >"$WORK/master.$name.log" 2>&1 & PIDS+=($!)
  for _ in $(seq 100); do rosnode list >/dev/null 2>&1 && break; sleep 0.1; done
  TRIGGER_FILE=$out/exchanging TRIGGER_ID=$N ROS_IP=10.213.0.1 \
    $PY tests/ros_status.py "$out" "${ROBOTS[@]}" >"$WORK/status.$name.log" 2>&1 & PIDS+=($!)
  declare -A NODE
  for r in "${ROBOTS[@]}"; do start_robot "$r" "$name"; NODE[$r]=$STARTED; done
  local rogue=""
  if [ "$name" = faults ]; then
    # It records 12 s of mission and attacks for 80 s of mission, whatever the rate.
    bg rogue "$ROGUE" --robots "$(seq -s, "$N")" --victim "$N" --record-s "$($PY -c "print(12 / $RATE)")" \
      --attack-s "$($PY -c "print(80 / $RATE)")" --takeover-when "$out/victim_down" \
      --out "$out/rogue.json" >"$WORK/rogue.log" 2>&1 & rogue=$!; PIDS+=("$rogue")
  fi
  local plays=()
  for r in "${ROBOTS[@]}"; do
    bg "$r" rosbag play -q -r "$RATE" --wait-for-subscribers "$WORK/bags/$r.bag" \
      --topics "/$r/points" "/$r/labels" "/$r/camera_info" "/$r/odometry" /tf_static >"$WORK/play_$r.$name.log" 2>&1 &
    plays+=($!); PIDS+=($!)
  done
  local started=$SECONDS
  if [ "$name" = faults ]; then
    # The victim hangs (SIGSTOP: connections are accepted, nothing is answered) while a robot
    # is exchanging with it (a neighbour sees it Matched or KeyframesRequested; at 30 s at the
    # latest; tests/ros_status.py watches), so calls to it are outstanding and retried; 3 s later it dies (kill -9) and the
    # rogue takes its Deliver service, never answering. 12 s later the victim starts again from
    # its snapshot. Meanwhile, from 30 s to 40 s, robot 2's link is cut.
    ( sleep 30; ip link set "sf$$h12" down; echo "  $(( SECONDS - started )) s: r2's link cut"
      sleep 10; ip link set "sf$$h12" up; echo "  $(( SECONDS - started )) s: r2's link back" ) &
    local cut=$!
    for _ in $(seq 1500); do [ -e "$out/exchanging" ] && break; sleep 0.02; done
    kill -STOP "${NODE[$VICTIM]}"
    echo "  $(( SECONDS - started )) s: $VICTIM hangs (kill -STOP)"
    cp "$out/$VICTIM.json" "$out/$VICTIM.before_kill.json" 2>/dev/null || echo '{}' > "$out/$VICTIM.before_kill.json"
    sleep 3
    kill -KILL "${NODE[$VICTIM]}"; wait "${NODE[$VICTIM]}" 2>/dev/null || true
    touch "$out/victim_down"
    echo "  $(( SECONDS - started )) s: $VICTIM killed (kill -9)"
    sleep 12
    start_robot "$VICTIM" faults2; NODE[$VICTIM]=$STARTED
    echo "  $(( SECONDS - started )) s: $VICTIM started again"
    wait "$cut"
  fi
  for p in "${plays[@]}"; do wait "$p" || fail "rosbag play in $name"; done
  echo "  $(( SECONDS - started )) s: bags played"
  [ -n "$rogue" ] && { wait "$rogue" || { cat "$WORK/rogue.log"; fail "the rogue"; }; }
  # Settle: until every robot has nothing pending and every status is fresh (or 60 s).
  for _ in $(seq 60); do
    sleep 1
    $PY - "$out" "${ROBOTS[@]}" <<'PY' && break
import json, sys
out, robots = sys.argv[1], sys.argv[2:]
for r in robots:
    s = json.load(open(f"{out}/{r}.json"))
    if any(l["pending"] for l in s["comms"]["keyframe_ledger"].values()):
        sys.exit(1)
PY
  done
  sleep 2
  for r in "${ROBOTS[@]}"; do echo "${NODE[$r]}" > "$out/$r.pid"; cpu_s "${NODE[$r]}" > "$out/$r.cpu"; done
  stop_all
}

for p in $PHASES; do echo "== phase: $p"; phase "$p"; done

echo "== checks"
$PY - "$WORK" "$VICTIM" "$PHASES" "${ROBOTS[@]}" <<'PY' || fail "see above"
import json, sys
work, victim, phases, robots = sys.argv[1], sys.argv[2], sys.argv[3].split(), sys.argv[4:]
ids = {r: int(r[1:]) for r in robots}
EPOCH = 1_700_000_000  # scenario bags start here (sgm_bridge::convert::time::SCENARIO_EPOCH)
def status(phase, r):
    return json.load(open(f"{work}/{phase}/{r}.json"))
def aligned(s):
    return {n["robot"]: n["first_aligned"] - EPOCH for n in s["neighbours"] if n["state"] == "Aligned"}
problems, figures = [], {"robots": len(robots), "links": open(f"{work}/shape").read().strip(), "phases": {}}
for phase in phases:
    rows = {}
    for r in robots:
        s = status(phase, r)
        sent = s["comms"]["sent"]
        rows[r] = {
            "aligned_at_s": aligned(s),
            "frames": s["sync"]["frames"],
            "clouds": int(open(f"{work}/{r}.clouds").read()),
            "bytes_sent": sum(v["bytes_total"] for v in sent["by_kind"].values()),
            "cpu_s": float(open(f"{work}/{phase}/{r}.cpu").read()),
            "keyframes": s["keyframes"],
            "ledger": s["comms"]["keyframe_ledger"],
            "rejected": s["comms"]["rejected"],
            "peers": s["transport"].get("peers", {}),
            "timeline": s.get("timeline"),
        }
    figures["phases"][phase] = rows
    print(f"  {phase}:")
    for r, row in rows.items():
        times = ", ".join(f"r{n}@{t:.0f}s" for n, t in sorted(row["aligned_at_s"].items()))
        print(f"    {r}: {row['frames']}/{row['clouds']} frames, {row['keyframes']} keyframes, "
              f"aligned with {times or 'nobody'}; {row['bytes_sent']} B sent, {row['cpu_s']:.1f} s CPU")
    for r, row in rows.items():
        for n, l in row["ledger"].items():
            if l["pending"]:
                problems.append(f"{phase}: {r}'s ledger with robot {n} still has {l['pending']} pending: {l}")
duration = float(open(f"{work}/duration").read())
clean = figures["phases"].get("clean")
faults = figures["phases"].get("faults")
if clean:
    for r, row in clean.items():
        if row["frames"] != row["clouds"]:
            problems.append(f"clean: {r} assembled {row['frames']} of {row['clouds']} clouds")
        if not row["aligned_at_s"]:
            problems.append(f"clean: {r} aligned with nobody")
if faults:
    rogue = json.load(open(f"{work}/faults/rogue.json"))
    print(f"  rogue: {rogue}")
    if rogue["calls_held"] == 0:
        problems.append("the rogue's never-answering Deliver service was never called")
    for r, row in faults.items():
        if r == victim:
            continue
        if row["frames"] != row["clouds"]:
            problems.append(f"faults: {r} assembled {row['frames']} of {row['clouds']} clouds (frames lost)")
        want = clean[r]["aligned_at_s"] if clean else {}
        for n, t_clean in want.items():
            t = row["aligned_at_s"].get(n)
            if f"r{n}" == victim or t_clean > duration / 2:
                # The victim lost the mission between its snapshot and its restart, and a pair
                # that aligned only in the mission's second half has no room for 2x: reported.
                print(f"    {r} ← r{n}: aligned at {t} s (clean {t_clean:.0f} s), not required")
            elif t is None:
                problems.append(f"faults: {r} never aligned with r{n} (clean: {t_clean:.0f} s)")
            elif "r2" in (r, f"r{n}"):
                # Robot 2's link was cut for 10 s: it must align, in whatever time that takes.
                print(f"    {r} ← r{n}: aligned at {t:.0f} s (clean {t_clean:.0f} s; r2's link was cut)")
            elif t > 2 * t_clean:
                problems.append(f"faults: {r} aligned with r{n} at {t:.0f} s, more than 2 × the clean {t_clean:.0f} s")
        rej = row["rejected"]
        # The node drops team-topic envelopes that claim to be its own before Comms sees them.
        forged = sum(c for f, c in rogue["broadcast_forged_as"].items() if f != str(ids[r])) \
            + rogue["delivered_forged"].get(str(ids[r]), 0)
        replayed = sum(c for f, c in rogue["broadcast_replayed_from"].items() if f != str(ids[r])) \
            + rogue["delivered_replayed"].get(str(ids[r]), 0)
        # A robot whose link was cut lost some of them on the way: it is only reported.
        if r != "r2" and (rej["bad_mac"] < forged or rej["replayed"] < replayed):
            problems.append(f"faults: {r} refused {rej['bad_mac']} forged (of {forged} sent) and "
                            f"{rej['replayed']} replayed (of {replayed} sent)")
        print(f"    {r}: refused {rej['bad_mac']} bad MACs (rogue sent {forged}), {rej['replayed']} replays "
              f"(rogue sent {replayed}); peers {dict((p, v['downs']) for p, v in row['peers'].items())} downs")
    v = faults[victim]
    before = json.load(open(f"{work}/faults/{victim}.before_kill.json"))
    log = open(f"{work}/{victim}.faults2.log").read()
    import re
    m = re.search(r"continuing from a snapshot.*?keyframes=(\d+)", re.sub(r"\x1b\[[0-9;]*m", "", log))
    if not m:
        problems.append(f"{victim} did not resume from its snapshot")
    else:
        kept = int(m.group(1))
        print(f"    {victim}: {before.get('keyframes')} keyframes before kill -9, {kept} in its snapshot, "
              f"{v['keyframes']} at the end")
        if v["keyframes"] < kept:
            problems.append(f"{victim} ended with {v['keyframes']} keyframes, fewer than its snapshot's {kept}")
    if not v["aligned_at_s"]:
        problems.append(f"{victim} aligned with nobody after its restart")
    downs = sum(faults[r]["peers"].get(str(ids[victim]), {}).get("downs", 0) for r in robots if r != victim)
    figures["victim_marked_down"] = downs
json.dump(figures, open(f"{work}/fleet.json", "w"), indent=1)
for p in problems:
    print("  PROBLEM:", p)
sys.exit(1 if problems else 0)
PY
echo "ros fleet: all passed ($WORK/fleet.json)"
