# topo_planner: the two commands are `make demo` and `make test` (see README.md).
SHELL := /bin/bash
ROOT := $(CURDIR)
JOBS ?= 2
WS := $(ROOT)/build/ws
CATKIN_ARGS := -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=Release
BIN = $(1)/devel/lib/topo_planner
COMMA := ,

.PHONY: deps build test bench bench-env bench-topo bench-opt bench-replan bench-forest-gen bench-camera bench-flight bench-flight-forests bench-speed bench-speed-core bench-faults soak demo map-demo test-asan test-tsan test-sanitizers fuzz clean

deps:
	@bash scripts/install_deps.sh

# A catkin workspace under build/ whose src/topo_planner links to this repository's entries (see
# scripts/link_workspace.sh). build/CATKIN_IGNORE keeps a workspace that holds this repository in its
# own src/ from finding the package twice.
define make_ws
	@mkdir -p $(1)/src
	@touch $(ROOT)/build/CATKIN_IGNORE
	@bash scripts/link_workspace.sh $(ROOT) $(1)/src/topo_planner
endef

build: deps
	$(call make_ws,$(WS))
	cd $(WS) && catkin_make -j$(JOBS) $(CATKIN_ARGS)

# Builds and runs every gtest and rostest, then prints `N passed, N failed`.
test: build
	@rm -rf $(WS)/build/test_results
	cd $(WS) && catkin_make -j$(JOBS) $(CATKIN_ARGS) run_tests
	@/usr/bin/python3 scripts/test_summary.py $(WS)/build/test_results

bench: bench-env bench-topo bench-replan bench-opt bench-camera

bench-env: build
	$(call BIN,$(WS))/bench_env $(BENCH_ARGS)

bench-topo: build
	$(call BIN,$(WS))/bench_topo $(BENCH_ARGS)

# The simulated depth camera at 640 x 480 on one core: rasteriser vs raycast.
bench-camera: build
	$(call BIN,$(WS))/bench_camera $(BENCH_ARGS)

# The paper's Table I: table on stdout, results/replan_tasks.csv, results/replan_table1.{md,png}.
bench-replan: build
	@mkdir -p results
	cd $(WS) && catkin_make -j$(JOBS) $(CATKIN_ARGS) topo_planner_bench_replan_suite >/dev/null
	$(call BIN,$(WS))/bench_replan_suite --out $(ROOT)/results $(BENCH_ARGS)
	/usr/bin/python3 scripts/plot_replan.py results/replan_tasks.csv results/replan_table1.png

# The 900 forest_gen tasks (../shared/bench/forest_gen by default), every method.
FOREST_GEN ?= $(ROOT)/../shared/bench/forest_gen
bench-forest-gen: build
	@bash scripts/run_forest_gen.sh $(call BIN,$(WS))/bench_replan $(FOREST_GEN) $(ROOT)/results/forest_gen

bench-opt: build
	$(call BIN,$(WS))/bench_opt $(BENCH_ARGS)

# The closed-loop flight: simulator, planner and flight monitor in a seeded medium forest through the
# scenario's three goals (headless; rviz when $$DISPLAY is set). A line per goal, then the flight
# report; results/flight_demo{.csv,_events.csv,_map.csv,_reference.csv,_report.json,.png}. Exits
# non-zero on a collision or a goal not reached.
demo: build
	@mkdir -p results
	WS=$(WS) bash scripts/run_flight.sh --density medium --seed 1 --output-dir $(ROOT)/results --name flight_demo $(DEMO_ARGS)

# Mapping only: a simulated depth camera fused into an empty map (results/map_demo_esdf.png).
map-demo: build
	@mkdir -p results
	$(call BIN,$(WS))/map_demo --map $(ROOT)/test/data/forest0.bt --out $(ROOT)/results

# 36 closed-loop flights over kinds of world and sensing (scripts/bench_flight.py --suite worlds: six
# world styles x ideal and realistic sensing x seeds 1..3, 3 m/s, 3 goals each in the open or beside
# obstacles), one after the other, headless: results/bench_flight.md and a RESULT line. About an hour;
# not in CI. bench-flight-forests: the earlier 20 forest flights (seeds 1..10 at medium and high
# density, goals in the open), results in results/forests/.
bench-flight: build
	@mkdir -p results
	WS=$(WS) /usr/bin/python3 scripts/bench_flight.py --out $(ROOT)/results $(BENCH_ARGS)

bench-flight-forests: build
	@mkdir -p results/forests
	WS=$(WS) /usr/bin/python3 scripts/bench_flight.py --suite forests --out $(ROOT)/results/forests $(BENCH_ARGS)

# Speed (scripts/bench_speed.py): closed-loop flights over the six world styles x ideal and realistic sensing
# x max_vel 3, 5 and 7 (bench-flight's worlds and goals), headless: per group goals, collisions, clearance, mean
# speed, time above 0.8 max_vel, the speed account and mission time / oracle time; results/bench_speed.md,
# results/bench_speed_speeds.png and a RESULT line. About 35 minutes (36 flights); not in CI.
# bench-speed-core: the same worlds in the ROS-free closed loop (plan_manage/sim_flight.h, simulated time,
# seconds per flight): results/speed_core/bench_speed_core.md and a RESULT line.
bench-speed: build
	@mkdir -p results
	WS=$(WS) /usr/bin/python3 scripts/bench_speed.py --out $(ROOT)/results $(BENCH_ARGS)

bench-speed-core: build
	@mkdir -p results/speed_core
	WS=$(WS) /usr/bin/python3 scripts/bench_speed_core.py --out $(ROOT)/results/speed_core $(BENCH_ARGS)

# Fault injection (scripts/bench_faults.py): 20 seeded closed-loop flights in simulated time, each with
# a random schedule of faults (camera or odometry blackout, odometry jump, ROS time step, planner kill),
# plus the same flights without faults as the control: results/bench_faults.md (a table per fault kind)
# and a RESULT line. About half an hour (45 s a flight); not in CI.
bench-faults: build
	@mkdir -p results
	WS=$(WS) /usr/bin/python3 scripts/bench_faults.py --out $(ROOT)/results $(BENCH_ARGS)

# Soak (scripts/soak.py): one continuous simulated mission of 30 simulated minutes through a seeded
# high-density forest (goals cycling between its ends), in simulated time at 1.5x real time; every
# node's memory and CPU sampled every 10 s: results/soak/soak.md and a RESULT line. About 20 minutes;
# not in CI. SOAK_ARGS=--minutes 5 for a short one.
soak: build
	@mkdir -p results/soak
	cd $(WS) && . devel/setup.sh && /usr/bin/python3 $(ROOT)/scripts/soak.py --out $(ROOT)/results/soak $(SOAK_ARGS)

# The tests under AddressSanitizer + UBSan, and under ThreadSanitizer, in their own workspaces
# (RelWithDebInfo). Every instrumented process, the tests and the nodes rostest launches, writes its
# sanitizer reports to WS/sanitizer_logs (log_path, one file per process); each report counts as a
# failure in the summary line, beside the JUnit results. The rostests run in simulated time with the
# lockstep, so the slowdown changes only the wall time: TOPO_PLANNER_TIME_LIMIT_SCALE stretches their
# wall-clock hang guards (rostest time-limit, the tests' wall_timeout_s). test-sanitizers runs both and
# ends with one line over the two.
ASAN_SCALE ?= 4
TSAN_SCALE ?= 12
define sanitized_tests
	$(call make_ws,$(ROOT)/build/$(1))
	@rm -rf build/$(1)/build/test_results build/$(1)/sanitizer_logs && mkdir -p build/$(1)/sanitizer_logs
	cd build/$(1) && catkin_make -j$(JOBS) -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DTOPO_PLANNER_SANITIZE=$(2)
	cd build/$(1) && catkin_make -j$(JOBS) -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DTOPO_PLANNER_SANITIZE=$(2) tests
	cd build/$(1) && $(3) catkin_make -j$(JOBS) -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DTOPO_PLANNER_SANITIZE=$(2) run_tests
	@/usr/bin/python3 scripts/test_summary.py $(ROOT)/build/$(1)/build/test_results --sanitizer-logs $(ROOT)/build/$(1)/sanitizer_logs
endef
SAN_LOG = log_path=$(ROOT)/build/$(1)/sanitizer_logs/$(2):log_exe_name=1
test-asan: deps
	$(call sanitized_tests,ws_asan,address$(COMMA)undefined,TOPO_PLANNER_TIME_LIMIT_SCALE=$(ASAN_SCALE) TOPO_PLANNER_BUDGET_SCALE=$(ASAN_SCALE) \
	  ASAN_OPTIONS=detect_leaks=1:$(call SAN_LOG,ws_asan,asan) LSAN_OPTIONS=suppressions=$(ROOT)/scripts/lsan.supp \
	  UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1:$(call SAN_LOG,ws_asan,ubsan))

test-tsan: deps
	$(call sanitized_tests,ws_tsan,thread,TOPO_PLANNER_TIME_LIMIT_SCALE=$(TSAN_SCALE) TOPO_PLANNER_BUDGET_SCALE=$(TSAN_SCALE) \
	  TSAN_OPTIONS="halt_on_error=1 suppressions=$(ROOT)/scripts/tsan.supp $(subst :, ,$(call SAN_LOG,ws_tsan,tsan))")

test-sanitizers: deps
	-$(MAKE) --no-print-directory test-asan
	-$(MAKE) --no-print-directory test-tsan
	@echo "test-sanitizers: ASan + UBSan and TSan together:"
	@/usr/bin/python3 scripts/test_summary.py build/ws_asan/build/test_results build/ws_tsan/build/test_results \
	  --sanitizer-logs build/ws_asan/sanitizer_logs --sanitizer-logs build/ws_tsan/sanitizer_logs

# libFuzzer harnesses of test/fuzz (clang-14, ASan + UBSan, build/ws_fuzz): each for FUZZ_S seconds on
# a copy of its corpus; a table (execs/s, coverage, corpus, crashes) and a RESULT line; non-zero exit
# on a crash (its input in build/fuzz/<name>/crashes/). FUZZ_TARGETS="pcd params" picks harnesses.
FUZZ_S ?= 60
fuzz: deps
	FUZZ_S=$(FUZZ_S) FUZZ_JOBS=$(JOBS) bash scripts/fuzz.sh

clean:
	rm -rf build
