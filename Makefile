# The one entry point. On a fresh Debian 12 machine, as root:
#   make demo   set up, build, and run the fleet demo (report in out/)
#   make test   set up, build, and run every test (gtest, pytest, rostest)
# setup installs Debian's packages and builds upstream move_base and Stage where the distribution
# lacks them (upstream/README.md: about 5-9 minutes the first time, seconds after).
SHELL := /bin/bash
PY := /usr/bin/python3
WS := catkin_ws
ENV := source scripts/env.sh &&
JOBS ?= 2

.PHONY: setup build test bench demo clean

setup:
	bash scripts/setup.sh

# Our workspace on top of the upstream stack setup built (or the distribution's).
build:
	JOBS=$(JOBS) bash scripts/build.sh

# Every test: gtest, pytest and rostest. Prints one closing line
# "N passed, N failed, N skipped" and fails if a test failed or none ran.
test: setup build
	$(ENV) $(PY) scripts/run_tests.py $(TEST_ARGS)

# All benchmarks, or one: make bench NAME=core
bench: build
	$(ENV) $(PY) scripts/run_bench.py $(NAME)

demo: setup build
	$(ENV) $(PY) scripts/run_demo.py

clean:
	rm -rf $(WS)/build $(WS)/devel $(WS)/install out
