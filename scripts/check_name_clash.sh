#!/usr/bin/env bash
# The name-clash check of `make test`: topo_planner built in one catkin workspace beside a package
# whose targets, library files and header folders are named like Fast-Planner's and EGO-Planner's
# (test/name_clash/fast_planner_names: plan_env, bspline_opt, path_searching, traj_server), with
# catkin_make (one CMake project: target names are global) and with catkin build (one devel/lib:
# library file names are shared). Each builds both packages' libraries and one executable of each,
# then runs them with rosrun from the workspace: topo_planner's flight_world (plan_env and
# path_searching: it writes a world and its goals) and the fixture's traj_server (prints the modules
# it linked). The workspace also holds quadrotor_msgs and mavros_msgs with the public layouts of
# the messages topo_planner publishes when they are found (test/name_clash/, Debian 12 has
# neither): topo_planner's plan_manage_test_setpoint_messages is built against them and run.
#
#   scripts/check_name_clash.sh ROOT WORKDIR [XUNIT_FILE]
#
# Exit status 0 when both build systems pass (a tool that is not installed fails the check). With
# XUNIT_FILE, writes the result there as JUnit XML, one test case per build system (catkin's
# run_tests reads it).
set -uo pipefail
# shellcheck source=scripts/junit.sh
source "$(dirname "${BASH_SOURCE[0]}")/junit.sh"

ROOT=$(cd "$1" && pwd)
WORK=$2
XUNIT=${3:-}
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd)
JOBS=${JOBS:-2}

run_case() {  # name, then the build commands (run in a clean environment in the workspace)
  local name=$1 build=$2
  local ws=$WORK/$name log=$WORK/$name.log
  rm -rf "$ws"
  mkdir -p "$ws/src"
  bash "$ROOT/scripts/link_workspace.sh" "$ROOT" "$ws/src/topo_planner" >/dev/null
  cp -r "$ROOT/test/name_clash/fast_planner_names" "$ROOT/test/name_clash/quadrotor_msgs" \
    "$ROOT/test/name_clash/mavros_msgs" "$ws/src/"
  # A clean environment: nothing of an enclosing catkin build (CMAKE_PREFIX_PATH, ROS_PACKAGE_PATH).
  if ! env -i HOME="$HOME" PATH=/usr/local/bin:/usr/bin:/bin LANG=C.UTF-8 bash -c "cd '$ws' && $build" >"$log" 2>&1; then
    status[$name]=fail
    message[$name]="build failed: $(grep -m3 -iE 'error|failed' "$log" | tr '\n' ' ' | cut -c1-400) (log: $log)"
    return
  fi
  local out
  out=$(env -i HOME="$HOME" PATH=/usr/local/bin:/usr/bin:/bin LANG=C.UTF-8 bash -c "
    source '$ws/devel/setup.bash' &&
    rosrun topo_planner flight_world --style windows --density medium --seed 1 --goals 2 --out '$ws/world.bt' &&
    rosrun fast_planner_names traj_server &&
    rosrun topo_planner topo_planner_plan_manage_test_setpoint_messages" 2>>"$log")
  if ! grep -q '^GOALS ' <<<"$out" || [ ! -s "$ws/world.bt" ]; then
    status[$name]=fail
    message[$name]="topo_planner's flight_world did not run (log: $log)"
  elif ! grep -q 'fast_planner::plan_env fast_planner::bspline_opt fast_planner::path_searching' <<<"$out"; then
    status[$name]=fail
    message[$name]="the fixture's traj_server did not run (log: $log)"
  elif ! grep -q '\[  PASSED  \] 2 tests' <<<"$out"; then
    status[$name]=fail
    message[$name]="the setpoint message tests (quadrotor_msgs, mavros_msgs) did not both pass (log: $log)"
  elif [ ! -e "$ws/devel/lib/libplan_env.so" ] || [ ! -e "$ws/devel/lib/libtopo_planner_plan_env.so" ]; then
    status[$name]=fail
    message[$name]="devel/lib lacks libplan_env.so or libtopo_planner_plan_env.so"
  else
    status[$name]=pass
    message[$name]="both packages built and ran"
  fi
}

CMAKE_ARGS="-DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=Release"
TARGETS="topo_planner_flight_world topo_planner_plan_manage_test_setpoint_messages"
run_case catkin_make \
  "catkin_make -j$JOBS $CMAKE_ARGS $TARGETS traj_server"
if command -v catkin >/dev/null 2>&1; then
  run_case catkin_build \
    "catkin init >/dev/null && catkin config --cmake-args $CMAKE_ARGS >/dev/null &&
     catkin build --no-status --no-notify -j$JOBS -p1 fast_planner_names mavros_msgs quadrotor_msgs &&
     catkin build --no-status --no-notify -p1 --no-deps topo_planner --make-args -j$JOBS $TARGETS"
else
  status[catkin_build]=fail
  message[catkin_build]="catkin build (Debian package catkin-tools) is not installed"
fi

names=(catkin_make catkin_build)
finish_checks "name clash" name_clash "$XUNIT"
