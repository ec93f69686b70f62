#!/usr/bin/env bash
# Makes DEST (a catkin workspace's src/topo_planner) a directory of links to the entries of the
# repository REPO, leaving out build/, results/ and .git. A single link to the repository itself
# would loop (the workspace lives in REPO/build), and ROS tools that walk a package with
# followlinks=True (rostest/roslaunch resolving node executables) would never return.
set -euo pipefail
repo=$(cd "$1" && pwd)
dest=$2
[ -L "$dest" ] && rm -f "$dest"   # the old single-link layout
mkdir -p "$dest"
for entry in "$repo"/* "$repo"/.[!.]*; do
  [ -e "$entry" ] || continue
  name=$(basename "$entry")
  case "$name" in build|results|.git) continue ;; esac
  ln -sfn "$entry" "$dest/$name"
done
# Drop links to entries that no longer exist.
for link in "$dest"/* "$dest"/.[!.]*; do
  [ -L "$link" ] && [ ! -e "$link" ] && rm -f "$link"
done
exit 0
