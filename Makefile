# The two commands of the README. Both set everything up themselves
# (scripts/setup.sh is idempotent and quick when nothing changed).
# PYTHON=python3.12 chooses the interpreter of a new .venv; VENV=... WS=...
# put the virtual environment and the colcon workspace elsewhere (e.g. a
# second Python next to the first, as .ci/run does); TESTS=... runs a subset
# (default: the system tests, tests/, and every package's unit tests, src/*/test). PYTEST_WORKERS=N runs
# the tests in N processes (pytest-xdist, a test file per process at a time,
# each with its own ROS_DOMAIN_ID); 0 runs them in this one.
SHELL := /bin/bash
.DEFAULT_GOAL := help
VENV ?= .venv
WS ?= ros2_ws
TESTS ?= tests $(wildcard src/*/test)
PYTEST_WORKERS ?= 2
ENV := . $(WS)/env.sh &&

.PHONY: help setup demo test bench mutation clean

help:
	@echo "make demo   set up, then drive the simulated HAMR headless; prints a table, writes a plot"
	@echo "make test   set up, then run the whole test suite"
	@echo "make bench  set up, then run the benchmarks (about 6 min); writes docs/benchmarks.md"
	@echo "make mutation  mutation testing of the ROS-free core (long: see docs/testing.md)"
	@echo "make setup  only set up $(VENV)/ and build $(WS)/ (PYTHON=python3.12 for another Python)"
	@echo "make clean  remove $(VENV)/, $(WS)/ and out/"

setup:
	@VENV="$(VENV)" WS="$(WS)" scripts/setup.sh

demo: setup
	@$(ENV) holonomic-demo --robot $(if $(ROBOT),$(ROBOT),hamr) --out out

test: setup
	@$(ENV) python -m pytest $(TESTS) -q -n $(PYTEST_WORKERS) --dist loadfile $(PYTEST_ARGS)

bench: setup
	@$(ENV) python bench/run.py $(BENCH_ARGS)

# MUTATION_ARGS: some modules only, e.g. MUTATION_ARGS="limits monitor"
mutation: setup
	@$(ENV) python scripts/mutation.py $(MUTATION_ARGS)

clean:
	rm -rf $(VENV) $(WS) out .pytest_cache .hypothesis
	find src -name '_hot_path*.so' -delete
