# Entry points a fresh Debian bookworm clone needs: every target installs what is missing, configures and builds.
#   make demo   synthetic lidar stream -> map-mode sampling with normals -> PLY -> verify -> per-level summary
#   make test   every test (GoogleTest suites and ROS tests) through ctest
# catkin and rostest need Debian's python3, not a pyenv one that may come first on PATH.
export PATH := /usr/bin:/bin:$(PATH)

BUILD ?= build
JOBS ?= 2
DEMO_DIR ?= $(BUILD)/demo
HPDS := $(BUILD)/hpds_core/hpds

.PHONY: all deps configure build test demo bench clean

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

# Performance against PCL on the real frames and a 5 M point synthetic stream; prints a table, writes JSON.
bench: build
	@$(BUILD)/bench/perf_benchmark --data ../shared/data/lidar --json $(BUILD)/bench/perf.json

demo: build
	@scripts/demo.sh $(HPDS) $(DEMO_DIR)

clean:
	rm -rf $(BUILD)
