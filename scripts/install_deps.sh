#!/usr/bin/env bash
# Installs the Debian 12 packages topo_planner needs (ROS 1 from Debian's own packages, in /usr).
# Idempotent and non-interactive: it installs only what is missing, and does nothing when all is
# present. Needs root (or sudo) only when something is missing.
set -euo pipefail

PACKAGES=(
  # build
  build-essential cmake catkin python3-catkin-pkg googletest libgtest-dev
  catkin-tools  # catkin build, for the name-clash check of make test
  # ROS 1 (Debian)
  ros-base-dev libroscpp-dev rosout rosbash python3-roslaunch python3-rostest librostest-dev
  ros-message-generation ros-message-runtime libmessage-filters-dev
  python3-geometry-msgs python3-nav-msgs python3-sensor-msgs  # rostest nodes in Python (planner_inputs_test.py)
  libstd-msgs-dev libgeometry-msgs-dev libsensor-msgs-dev libnav-msgs-dev libvisualization-msgs-dev
  libtf2-ros-dev libtf2-eigen-dev libtf2-geometry-msgs-dev libpcl-conversions-dev libcv-bridge-dev
  libdiagnostic-updater-dev libdiagnostic-msgs-dev  # /diagnostics of the mapping and the planner
  libdynamic-reconfigure-config-init-mutex-dev python3-dynamic-reconfigure  # the planner's limits at run time
  rviz
  python3-rosbag  # planner.launch record:=true, the record-and-replay check
  # algorithms and maps
  libeigen3-dev libnlopt-cxx-dev liboctomap-dev libdynamicedt3d-dev libpcl-dev libopencv-dev
  libyaml-cpp-dev  # config/*.yaml read by the ROS-free closed loop (plan_manage/sim_flight.h)
  # headless demo and figures
  xvfb python3-matplotlib
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "install_deps: missing packages (${missing[*]}) and not root; run as root" >&2
    exit 1
  fi
fi

echo "install_deps: installing ${#missing[@]} packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "install_deps: done"
