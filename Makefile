# Entry points a fresh Debian bookworm clone needs: every target installs what is missing, configures and builds.
#   make demo   synthetic lidar stream -> map-mode sampling with normals -> PLY -> verify -> per-level summary
#   make test   every test (GoogleTest suites and ROS tests) through ctest
#   make test-sanitize   the same tests, node and ROS tests included, built with AddressSanitizer +
#                        UndefinedBehaviorSanitizer (in build/asan/: under build/,
#                        which rosrun does not search, so `rosrun hpds hpds_node` never finds a sanitized binary)
#   make test-tsan   the core's tests (no ROS node) built with ThreadSanitizer (in build/tsan/): the pipeline's
#                    second thread, the parallel normals, scan-mode workers, the tiled builds
#   make fuzz   libFuzzer targets for every parser of outside data, FUZZ_SECONDS each (in build/fuzz/)
#   make registration   scan matching (PCL ICP/GICP) on hpds levels vs voxel grids at equal point count
# catkin and rostest need Debian's python3, not a pyenv one that may come first on PATH.
export PATH := /usr/bin:/bin:$(PATH)

BUILD ?= build
JOBS ?= 2
DEMO_DIR ?= $(BUILD)/demo
ASAN_BUILD ?= build/asan
TSAN_BUILD ?= build/tsan
FUZZ_BUILD ?= build/fuzz
FUZZ_SECONDS ?= 60
# The node, the nodelet and their ROS tests are sanitized too whenever ROS is installed (the tests that start Debian's
# uninstrumented nodelet manager preload the sanitizer runtimes for it); ASAN_NODE=OFF leaves them out.
ASAN_NODE ?=
ASAN_NODE_FLAG := $(if $(ASAN_NODE),-DHPDS_BUILD_NODE=$(ASAN_NODE),-UHPDS_BUILD_NODE)
HPDS := $(BUILD)/hpds

.PHONY: all deps configure build test test-sanitize test-tsan fuzz demo bench clean

all: build

deps:
	@scripts/install-deps.sh

configure: deps
	@mkdir -p $(BUILD)
	@cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release > $(BUILD)/configure.log 2>&1 || { cat $(BUILD)/configure.log; exit 1; }

build: configure
	@cmake --build $(BUILD) -j$(JOBS)

test: build
	@cd $(BUILD) && ctest --output-on-failure -j$(JOBS) --timeout 900

# Any ASan/UBSan report aborts its test (UB is non-recoverable in that build), so "no failures" means "no reports".
test-sanitize: deps
	@mkdir -p $(ASAN_BUILD)
	@cmake -S . -B $(ASAN_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DHPDS_SANITIZE=ON $(ASAN_NODE_FLAG) > $(ASAN_BUILD)/configure.log 2>&1 || { cat $(ASAN_BUILD)/configure.log; exit 1; }
	@cmake --build $(ASAN_BUILD) -j$(JOBS)
	@cd $(ASAN_BUILD) && ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
	  ctest --output-on-failure -j$(JOBS) --timeout 1800

# Any report fails its test (halt_on_error). PCL's OpenNI2 dependency, not built with TSan, is suppressed
# (test/tsan.supp); the setting is needed while building too, as gtest_discover_tests runs every test binary.
TSAN_ENV := TSAN_OPTIONS="suppressions=$(CURDIR)/test/tsan.supp halt_on_error=1 second_deadlock_stack=1"
test-tsan: deps
	@mkdir -p $(TSAN_BUILD)
	@cmake -S . -B $(TSAN_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DHPDS_TSAN=ON -DHPDS_BUILD_NODE=OFF -DHPDS_BUILD_PYTHON=OFF -DHPDS_BUILD_BENCH=OFF > $(TSAN_BUILD)/configure.log 2>&1 || { cat $(TSAN_BUILD)/configure.log; exit 1; }
	@$(TSAN_ENV) cmake --build $(TSAN_BUILD) -j$(JOBS)
	@cd $(TSAN_BUILD) && $(TSAN_ENV) ctest --output-on-failure -j$(JOBS) --timeout 1800

fuzz: deps
	@FUZZ_BUILD=$(FUZZ_BUILD) FUZZ_SECONDS=$(FUZZ_SECONDS) JOBS=$(JOBS) scripts/fuzz.sh

# Performance against PCL on the real frames and a 5 M point synthetic stream; prints a table, writes JSON.
bench: build
	@cmake --build $(BUILD) -j$(JOBS) --target perf_benchmark
	@$(BUILD)/bench/perf_benchmark --data ../shared/data/lidar --json $(BUILD)/bench/perf.json

demo: build
	@scripts/demo.sh $(HPDS) $(DEMO_DIR)

# Sampling quality, measured (docs/quality.md): normal accuracy against ground truth, feature-sensitive
# levels, blue-noise analysis against grid baselines; tables, plots and pictures in $(BUILD)/quality/.
.PHONY: quality
quality: build
	@cmake --build $(BUILD) -j$(JOBS) --target normal_accuracy feature_sensitivity plane_sampling
	@scripts/quality.sh $(BUILD) $(BUILD)/quality $(JOBS)

# Registration at equal point count (docs/quality.md, Registration): PCL point-to-plane ICP and GICP on hpds levels
# against voxel grids, from perturbed starts and the identity, and coarse to fine over the levels; tables in
# $(BUILD)/quality/registration/. About 2 CPU minutes; not part of make test.
.PHONY: registration
registration: build
	@cmake --build $(BUILD) -j$(JOBS) --target registration_benchmark
	@$(BUILD)/bench/registration_benchmark --data ../shared/data/lidar --out $(BUILD)/quality/registration

clean:
	rm -rf $(BUILD)
