#!/usr/bin/env bash
# Flies one simulated flight and reports it: roslaunch topo_planner simulation.launch with the flight
# monitor, waits for the monitor to end the launch (it is `required` and shuts down when the flight is
# over), then plots the flight and prints the report. Exits 0 only if the report says success (every
# goal reached, no collision).
#
#   run_flight.sh [--density low|medium|high] [--map-style forest|walls|rings|windows|boxes|mixed] [--seed N] [--goals "x y z x y z ..."] [--start "x y z"]
#                 [--max-vel M/S] [--goal-timeout S] [--output-dir DIR] [--name NAME] [--rviz true|false]
#                 [--sim-time true|false] [--realtime-factor F] [--master-port PORT] [--timeout S] [--verbose]
#                 [--no-plot] [-- roslaunch args...]
#
# Files: DIR/NAME.csv, NAME_events.csv, NAME_map.csv, NAME_reference.csv, NAME_report.json, NAME.png.
# Faults (simulation.launch's depth_blackouts:=, odom_blackouts:=, odom_jumps:=, clock_steps:=,
# faults_start_on_speed:=, planner_respawn:=) go after --; --master-port fixes the private master's
# port (scripts/bench_faults.py talks to the flight through it), --realtime-factor the sim-time pace.
# rviz opens when $DISPLAY is set (unless --rviz false). The launch gets its own ROS master on a free
# port, so flights never talk to another roscore on the machine. --timeout (default: goals x
# goal timeout + 180 s, times $TOPO_PLANNER_TIME_LIMIT_SCALE) is a wall-clock guard against a hung
# simulation only; the monitor's per-goal
# limit decides a failed goal. The other nodes log to ~/.ros/log unless --verbose.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WS=${WS:-$ROOT/build/ws}

density=medium
map_style=forest
seed=1
goals=""
start=""
max_vel=""
goal_timeout=90
output_dir=$ROOT/results
name=flight
rviz=""
sim_time=false
realtime_factor=""
port=""
timeout_s=""
verbose=false
plot=true
extra=()

while [ $# -gt 0 ]; do
  case "$1" in
    --density) density=$2; shift 2 ;;
    --map-style) map_style=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --goals) goals=$2; shift 2 ;;
    --start) start=$2; shift 2 ;;
    --max-vel) max_vel=$2; shift 2 ;;
    --goal-timeout) goal_timeout=$2; shift 2 ;;
    --output-dir) output_dir=$2; shift 2 ;;
    --name) name=$2; shift 2 ;;
    --rviz) rviz=$2; shift 2 ;;
    --sim-time) sim_time=$2; shift 2 ;;
    --realtime-factor) realtime_factor=$2; shift 2 ;;
    --master-port) port=$2; shift 2 ;;
    --timeout) timeout_s=$2; shift 2 ;;
    --verbose) verbose=true; shift ;;
    --no-plot) plot=false; shift ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,21p' "$0"; exit 0 ;;
    *) echo "run_flight: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done

if [ ! -f "$WS/devel/setup.bash" ]; then
  echo "run_flight: no workspace at $WS (run make build, or set WS)" >&2
  exit 2
fi
set +u  # setup.bash reads unset variables
# shellcheck disable=SC1091
source "$WS/devel/setup.bash"
set -u

# "x y z x y z" -> "[x, y, z, x, y, z]" (the launch file's YAML lists).
yaml_list() {
  local -a v
  read -r -a v <<<"$1"
  local IFS=,
  echo "[${v[*]}]" | sed 's/,/, /g'
}
count_words() { local -a v; read -r -a v <<<"$1"; echo "${#v[@]}"; }

if [ -z "$rviz" ]; then
  if [ -n "${DISPLAY:-}" ]; then rviz=true; else rviz=false; fi
fi
n_goals=3
if [ -n "$goals" ]; then
  n=$(count_words "$goals")
  if [ $((n % 3)) -ne 0 ] || [ "$n" -eq 0 ]; then
    echo "run_flight: --goals needs x y z triples, got $n numbers" >&2
    exit 2
  fi
  n_goals=$((n / 3))
fi
if [ -z "$timeout_s" ]; then
  # Stretched like the rostests' hang guards on a slow machine (TOPO_PLANNER_TIME_LIMIT_SCALE).
  timeout_s=$(awk -v n="$n_goals" -v g="$goal_timeout" -v k="${TOPO_PLANNER_TIME_LIMIT_SCALE:-1}" \
    'BEGIN { if (!(k + 0 >= 1)) k = 1; printf "%d", (n * g + 180) * k }')
fi

args=(density:="$density" map_style:="$map_style" seed:="$seed" rviz:="$rviz" sim_time:="$sim_time" monitor:=true
      shutdown_when_done:=true output_dir:="$output_dir" name:="$name" goal_timeout:="$goal_timeout")
[ -n "$goals" ] && args+=(goals:="$(yaml_list "$goals")")
[ -n "$start" ] && args+=(start:="$(yaml_list "$start")")
[ -n "$max_vel" ] && args+=(max_vel:="$max_vel")
[ -n "$realtime_factor" ] && args+=(realtime_factor:="$realtime_factor")
[ "$verbose" = true ] || args+=(output:=log)
args+=("${extra[@]}")

mkdir -p "$output_dir"
for f in "$name.csv" "${name}_events.csv" "${name}_map.csv" "${name}_reference.csv" "${name}_report.json" "$name.png"; do
  rm -f "${output_dir:?}/$f"
done

# A private master on a free port.
if [ -z "$port" ]; then
  port=$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
fi
export ROS_MASTER_URI=http://127.0.0.1:$port
export ROS_HOSTNAME=127.0.0.1
unset ROS_IP

echo "run_flight: $name: density $density, style $map_style, seed $seed, ${n_goals} goals, rviz $rviz, master port $port, guard ${timeout_s} s"
echo "run_flight: roslaunch topo_planner simulation.launch ${args[*]}"
t0=$(date +%s)
# Without --verbose, roslaunch's parameter summary (a few hundred lines) is left out of the console.
filter() {
  if [ "$verbose" = true ]; then cat; return; fi
  awk '/^SUMMARY$/ { skip = 1; print "(roslaunch parameter summary hidden; --verbose shows it and every node'"'"'s log)" }
       /auto-starting new master|process\[master\]|process\[rosout/ { skip = 0 }
       !skip { print; fflush() }'
}
export PYTHONUNBUFFERED=1 ROSCONSOLE_STDOUT_LINE_BUFFERED=1  # lines as they come, also through the filter
timeout --signal=INT --kill-after=30 "$timeout_s" roslaunch -p "$port" topo_planner simulation.launch "${args[@]}" \
  > >(filter) 2>&1 &
pid=$!
trap 'kill -INT "$pid" 2>/dev/null || true' INT TERM
rc=0
wait "$pid" || rc=$?
while kill -0 "$pid" 2>/dev/null; do  # interrupted: wait for roslaunch to shut down
  wait "$pid" || rc=$?
done
trap - INT TERM
t1=$(date +%s)
if [ "$rc" -eq 124 ]; then
  echo "run_flight: the launch did not end within ${timeout_s} s of wall time: stopped" >&2
fi
echo "run_flight: roslaunch ended (exit $rc) after $((t1 - t0)) s"

report="$output_dir/${name}_report.json"
if [ ! -f "$report" ]; then
  echo "run_flight: no report $report: the flight monitor did not write one" >&2
  exit 2
fi
plot_args=("$output_dir" "$name" --print-report)
[ "$plot" = true ] || plot_args+=(--no-plot)
/usr/bin/python3 "$ROOT/scripts/plot_flight.py" "${plot_args[@]}"
