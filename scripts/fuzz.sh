#!/usr/bin/env bash
# make fuzz: builds the libFuzzer harnesses of test/fuzz with clang-14 + ASan + UBSan in their own
# workspace (build/ws_fuzz, -DTOPO_PLANNER_FUZZ=ON), runs each for FUZZ_S seconds on a copy of its
# seed corpus (build/fuzz/<name>/corpus), one after the other, and prints a table: execs/s, coverage
# (libFuzzer's cov = edges, ft = features), corpus size, crashes. A crash (or leak, timeout, OOM)
# leaves its input in build/fuzz/<name>/crashes/ and makes the exit status non-zero; fix the code,
# then copy the input to test/fuzz/regressions/<name>/ so that make test replays it.
# Environment: FUZZ_S (seconds per harness, default 60), FUZZ_TARGETS (names, default all),
# FUZZ_JOBS (build jobs, default 2), FUZZ_RSS_MB (default 2048).
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
FUZZ_S=${FUZZ_S:-60}
FUZZ_JOBS=${FUZZ_JOBS:-2}
FUZZ_RSS_MB=${FUZZ_RSS_MB:-2048}
all="octomap pcd tasks_csv depth_image pointcloud2 trajectory_msgs params plan_problem"
targets=${FUZZ_TARGETS:-$all}
ws=$root/build/ws_fuzz
out=$root/build/fuzz

command -v clang++-14 >/dev/null || { echo "fuzz: clang++-14 not found (apt-get install clang-14 libfuzzer-14-dev)"; exit 2; }
mkdir -p "$ws/src" && touch "$root/build/CATKIN_IGNORE"
bash "$root/scripts/link_workspace.sh" "$root" "$ws/src/topo_planner"
build_targets=""
for t in $targets; do build_targets="$build_targets topo_planner_fuzzer_$t"; done
( cd "$ws" && CC=clang-14 CXX=clang++-14 catkin_make -j"$FUZZ_JOBS" -DPYTHON_EXECUTABLE=/usr/bin/python3 \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTOPO_PLANNER_FUZZ=ON -DTOPO_PLANNER_SANITIZE=address,undefined \
    -DCATKIN_ENABLE_TESTING=OFF $build_targets ) > "$out.build.log" 2>&1 || {
  mkdir -p "$out"; tail -40 "$out.build.log"; echo "fuzz: build failed (log: $out.build.log)"; exit 2; }

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:allocator_may_return_null=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}
rows=()
total_crashes=0
n=0
for t in $targets; do
  exe=$ws/devel/lib/topo_planner/${t}_fuzzer
  dir=$out/$t
  rm -rf "$dir/corpus" "$dir/crashes" && mkdir -p "$dir/corpus" "$dir/crashes"  # crashes: this run's only
  cp "$root/test/fuzz/corpus/$t/"* "$dir/corpus/"
  seeds=$(ls "$dir/corpus" | wc -l)
  echo "fuzz: $t for ${FUZZ_S} s ($seeds seeds; log $dir/fuzz.log)"
  nice "$exe" -max_total_time="$FUZZ_S" -print_final_stats=1 -rss_limit_mb="$FUZZ_RSS_MB" -timeout=10 \
    -max_len=65536 -artifact_prefix="$dir/crashes/" "$dir/corpus" > "$dir/fuzz.log" 2>&1
  rc=$?
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$dir/fuzz.log" | tail -1)
  eps=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$dir/fuzz.log" | tail -1)
  last=$(grep -E '^#[0-9]+' "$dir/fuzz.log" | grep -E ' cov: ' | tail -1)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
  corp=$(ls "$dir/corpus" | wc -l)
  crashes=$(find "$dir/crashes" -type f | wc -l)
  if [ "$rc" -ne 0 ] && [ "$crashes" -eq 0 ]; then crashes=1; fi  # died without an artifact
  total_crashes=$((total_crashes + crashes))
  n=$((n + 1))
  rows+=("$(printf '| %-16s | %8s | %10s | %6s | %6s | %6s | %7s |' "$t" "${eps:-?}" "${execs:-?}" "${cov:-?}" "${ft:-?}" "$corp" "$crashes")")
  if [ "$crashes" -gt 0 ]; then
    echo "fuzz: $t FAILED: inputs in $dir/crashes/, report at the end of $dir/fuzz.log"
    grep -a -m3 -E 'ERROR: AddressSanitizer|ERROR: libFuzzer|runtime error|fuzz property violated' "$dir/fuzz.log"
  fi
done
echo
echo "| harness          | execs/s  | execs      | cov    | ft     | corpus | crashes |"
echo "|------------------|----------|------------|--------|--------|--------|---------|"
printf '%s\n' "${rows[@]}"
echo "RESULT harnesses=$n crashes=$total_crashes seconds_each=$FUZZ_S"
[ "$total_crashes" -eq 0 ]
