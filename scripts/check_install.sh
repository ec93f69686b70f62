#!/usr/bin/env bash
# The install-space check of `make test`: installs the built workspace (catkin_make install, i.e.
# cmake --install of its build directory, into its install/ space) and then, in a clean environment
# that sources only install/setup.bash (nothing of devel/ or of this source tree), shows that
#   - the package resolves to the install space (rospack find topo_planner -> install/share/topo_planner),
#   - its headers, libraries and launch/config files are there,
#   - a node runs from install/lib (rosrun topo_planner flight_world writes a world and its goals),
#   - a launch file runs from install/share: simulation.launch flies a short seeded forest mission
#     headless in simulated time with the flight monitor, which ends the launch and reports success.
#
#   scripts/check_install.sh BUILD_DIR WORKDIR [XUNIT_FILE]
#
# BUILD_DIR is the catkin build directory of a workspace whose targets are built (make test builds
# them first). Exit status 0 when every case passes; with XUNIT_FILE, the cases as JUnit XML.
set -uo pipefail
# shellcheck source=scripts/junit.sh
source "$(dirname "${BASH_SOURCE[0]}")/junit.sh"

BUILD=$(cd "$1" && pwd)
WORK=$2
XUNIT=${3:-}
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd)
PREFIX=$(sed -n 's/^CMAKE_INSTALL_PREFIX:PATH=//p' "$BUILD/CMakeCache.txt")
LOG=$WORK/install.log

# Runs a command in a clean environment with only the install space sourced.
in_install() {
  # A clean environment, but for the sanitizer runs' options (their log_path: a report of a node
  # flown from the install space counts like any other) and scales (without the time-limit scale the
  # simulator's lockstep waited 50 ms of wall time for the TSan controller, ran on, and the flight
  # from the install space timed out, its planner fed odometry from 0.64 s ahead).
  local keep=() v
  for v in ASAN_OPTIONS UBSAN_OPTIONS TSAN_OPTIONS LSAN_OPTIONS TOPO_PLANNER_BUDGET_SCALE TOPO_PLANNER_TIME_LIMIT_SCALE; do
    [ -n "${!v:-}" ] && keep+=("$v=${!v}")
  done
  env -i HOME="$HOME" PATH=/usr/local/bin:/usr/bin:/bin LANG=C.UTF-8 "${keep[@]}" bash -c "source '$PREFIX/setup.bash' && $1"
}

if [ -z "$PREFIX" ]; then
  record install fail "no CMAKE_INSTALL_PREFIX in $BUILD/CMakeCache.txt"
elif ! cmake --install "$BUILD" >"$LOG" 2>&1; then
  record install fail "cmake --install failed: $(grep -m3 -iE 'error' "$LOG" | tr '\n' ' ' | cut -c1-300) (log: $LOG)"
else
  missing=""
  for f in setup.bash share/topo_planner/package.xml share/topo_planner/launch/simulation.launch \
           share/topo_planner/launch/planner.launch share/topo_planner/config/planner.yaml \
           lib/libtopo_planner_plan_env.so lib/topo_planner/planner_node lib/topo_planner/mapping_node \
           include/topo_planner/plan_env/esdf_map.h include/topo_planner/topo_replan/replan_fsm.h \
           include/topo_planner/PositionCommand.h; do
    [ -e "$PREFIX/$f" ] || missing="$missing $f"
  done
  if [ -n "$missing" ]; then
    record install fail "not installed:$missing"
  else
    record install pass "installed into $PREFIX"
  fi
fi

if [ "${status[install]}" = pass ]; then
  found=$(in_install "rospack find topo_planner" 2>>"$LOG")
  if [ "$found" != "$PREFIX/share/topo_planner" ]; then
    record resolve fail "rospack find topo_planner gave '$found', not $PREFIX/share/topo_planner"
  else
    record resolve pass "rospack find topo_planner: $found"
  fi

  out=$(in_install "rosrun topo_planner flight_world --style windows --density medium --seed 1 --goals 2 --out '$WORK/world.bt'" 2>>"$LOG")
  if grep -q '^GOALS ' <<<"$out" && [ -s "$WORK/world.bt" ]; then
    record node pass "flight_world ran from $PREFIX/lib/topo_planner"
  else
    record node fail "flight_world did not run from the install space (log: $LOG)"
  fi

  # A short mission (12 m through the seeded medium forest), headless, simulated time at half real
  # time, its own master. The monitor is required: it ends the launch when the flight is over. The
  # 300 s hang guard stretches with TOPO_PLANNER_TIME_LIMIT_SCALE (the sanitizer runs: under TSan the
  # flight, in lockstep, outlasted 300 s of wall time).
  limit_s=$(awk -v s="${TOPO_PLANNER_TIME_LIMIT_SCALE:-1}" 'BEGIN { s = s + 0; if (s < 1) s = 1; printf "%d", 300 * s }')
  rm -f "$WORK/install_flight_report.json"
  port=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  in_install "export ROS_MASTER_URI=http://127.0.0.1:$port ROS_HOSTNAME=127.0.0.1 &&
    timeout --signal=INT --kill-after=20 $limit_s roslaunch -p $port topo_planner simulation.launch rviz:=false \
      sim_time:=true realtime_factor:=0.5 monitor:=true shutdown_when_done:=true output:=log \
      'goals:=[-3.0, 0.0, 1.0]' goal_timeout:=60 output_dir:='$WORK' name:=install_flight" >>"$LOG" 2>&1
  report=$WORK/install_flight_report.json
  if [ ! -s "$report" ]; then
    record launch fail "simulation.launch from the install space wrote no flight report (log: $LOG)"
  elif ! grep -q '"status": "kSuccess"' "$report"; then
    record launch fail "the flight from the install space did not succeed: $(grep -m1 '"message"' "$report" | cut -c1-200)"
  else
    record launch pass "simulation.launch flew a mission from $PREFIX/share/topo_planner"
  fi
fi

finish_checks "install space" install_space "$XUNIT"
