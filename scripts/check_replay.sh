#!/usr/bin/env bash
# The record-and-replay check of `make test` (docs/on_your_drone.md, "Record and replay"): a short
# simulated flight is recorded with planner.launch's record:=true, then its inputs are replayed with
# the bag's clock into a planner.launch of its own (no simulator), as docs/on_your_drone.md tells a
# user to, and the replay is compared with the flight (scripts/replay_compare.py):
#   record  the flight succeeded and its bag holds every input topic the replay needs
#   map     the replayed map is the flight's (the same occupied voxels)
#   route   the replayed planner found the flight's first global route
#   plans   the replayed planner published trajectories
#
#   scripts/check_replay.sh DEVEL_SETUP WORKDIR [XUNIT_FILE]
#
# DEVEL_SETUP is the setup.bash of a built workspace. Each launch has its own master on a free port.
# Exit status 0 when every case passes; with XUNIT_FILE, the cases as JUnit XML.
set -uo pipefail
# shellcheck source=scripts/junit.sh
source "$(dirname "${BASH_SOURCE[0]}")/junit.sh"
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

SETUP=$1
WORK=$2
XUNIT=${3:-}
rm -rf "$WORK"
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd)
LOG=$WORK/replay.log
set +u  # catkin's setup scripts read unset variables
# shellcheck disable=SC1090
source "$SETUP"
set -u
export ROS_HOSTNAME=127.0.0.1 ROS_LOG_DIR=$WORK/ros_log

free_port() { /usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
# Waits (at most $2 s) until the master on port $1 answers.
wait_master() {
  local i
  for ((i = 0; i < $2 * 10; ++i)); do
    ROS_MASTER_URI=http://127.0.0.1:$1 rostopic list >/dev/null 2>&1 && return 0
    sleep 0.1
  done
  return 1
}
stop() {  # SIGINT a process (and its group's children) and wait for it
  kill -INT "$1" 2>/dev/null
  for _ in $(seq 100); do kill -0 "$1" 2>/dev/null || return 0; sleep 0.1; done
  kill -KILL "$1" 2>/dev/null
}

INPUTS="/odom /camera/depth/image_rect_raw /camera/depth/camera_info /camera/pose /tf /tf_static /move_base_simple/goal /planning/waypoints"
# Under the sanitizers (make test-asan / test-tsan) every node runs several times slower: the hang
# guards stretch and the bag plays that much slower (rosbag play drives the clock; no lockstep).
SCALE=$(/usr/bin/python3 -c "import sys; print(max(1.0, float(sys.argv[1])))" "${TOPO_PLANNER_TIME_LIMIT_SCALE:-1}")
PLAY_RATE=$(/usr/bin/python3 -c "import sys; print(0.5 / float(sys.argv[1]))" "$SCALE")
FLIGHT_TIMEOUT=$(/usr/bin/python3 -c "import sys; print(int(300 * float(sys.argv[1])))" "$SCALE")
MAP_ARGS="map_origin:=[-20.0,-20.0,0.3] map_size:=[40.0,40.0,3.4] max_vel:=2.5 max_acc:=2.5"

# 1. The flight, 8 m through the seeded medium forest, in simulated time at half real time, with
#    planner.launch's recording and the test's own recording of the map the planner built.
port=$(free_port)
export ROS_MASTER_URI=http://127.0.0.1:$port
timeout --signal=INT --kill-after=20 "$FLIGHT_TIMEOUT" roslaunch -p "$port" topo_planner simulation.launch rviz:=false \
  sim_time:=true realtime_factor:=0.5 monitor:=true shutdown_when_done:=true output:=log \
  'goals:=[-7.0, 0.0, 1.0]' goal_timeout:=60 output_dir:="$WORK" name:=flight \
  record:=true bag_prefix:="$WORK/rec" >>"$LOG" 2>&1 &
launch=$!
if wait_master "$port" 30; then
  rosbag record -O "$WORK/map_flight.bag" /planner/mapping/occupancy >>"$LOG" 2>&1 &
  map_rec=$!
  wait "$launch"
  stop "$map_rec"
else
  stop "$launch"
fi
sleep 1  # planner.launch's recorder closes its bag on the launch's shutdown
flight_bag=$(ls "$WORK"/rec_*.bag 2>/dev/null | head -1)
report=$WORK/flight_report.json
if [ ! -s "$report" ] || ! grep -q '"status": "kSuccess"' "$report"; then
  record record fail "the recorded flight did not succeed (log: $LOG)"
elif [ -z "$flight_bag" ] || [ ! -s "$WORK/map_flight.bag" ]; then
  record record fail "no bag written: flight '$flight_bag', map $WORK/map_flight.bag (log: $LOG)"
else
  missing=$(/usr/bin/python3 - "$flight_bag" $INPUTS <<'EOF'
import sys, rosbag
topics = rosbag.Bag(sys.argv[1]).get_type_and_topic_info().topics
count = lambda t: topics[t].message_count if t in topics else 0
goals = ('/move_base_simple/goal', '/planning/waypoints')  # either: rviz's goal or the monitor's waypoints
missing = [t for t in sys.argv[2:] if t not in goals and count(t) == 0]
if not any(count(t) for t in goals):
    missing.append(' or '.join(goals))
print(' '.join(missing))
EOF
)
  if [ -n "$missing" ]; then
    record record fail "the flight's bag has no messages on: $missing"
  else
    record record pass "$(basename "$flight_bag"): $(du -h "$flight_bag" | cut -f1), the flight succeeded"
  fi
fi

# 2. The replay: planner.launch alone with use_sim_time, fed the bag's inputs with its clock.
if [ "${status[record]}" = pass ]; then
  port=$(free_port)
  export ROS_MASTER_URI=http://127.0.0.1:$port
  roslaunch -p "$port" topo_planner planner.launch use_sim_time:=true pose_type:=pose output:=log clear_map_on_odom_jump:=false \
    $MAP_ARGS >>"$LOG" 2>&1 &
  launch=$!
  ok=false
  if wait_master "$port" 30; then
    for _ in $(seq "${FLIGHT_TIMEOUT}"); do  # the planner is up when its heartbeat topic is advertised
      rostopic list 2>/dev/null | grep -q '^/planning/heartbeat$' && ok=true && break
      sleep 0.1
    done
  fi
  if $ok; then
    rosbag record -O "$WORK/replay.bag" /planner/mapping/occupancy /planning/global_route /planning/replan_event \
      >>"$LOG" 2>&1 &
    rec=$!
    sleep 2
    # shellcheck disable=SC2086
    rosbag play --clock -r "$PLAY_RATE" -q "$flight_bag" --topics $INPUTS >>"$LOG" 2>&1
    sleep 3
    stop "$rec"
  fi
  stop "$launch"
  if ! $ok; then
    record replay fail "the replay's planner did not start (log: $LOG)"
  else
    while IFS= read -r line; do
      case_name=${line%% *}
      rest=${line#* }
      verdict=${rest%%:*}
      record "$case_name" "$verdict" "${rest#*: }"
    done < <(/usr/bin/python3 "$HERE/replay_compare.py" "$WORK/map_flight.bag" "$flight_bag" "$WORK/replay.bag" 2>>"$LOG")
    [ -n "${status[map]:-}" ] || record compare fail "replay_compare.py gave no result (log: $LOG)"
  fi
fi

finish_checks "record and replay" record_replay "$XUNIT"
