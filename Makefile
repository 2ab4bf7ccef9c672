# The two commands of the README. Both set everything up themselves
# (scripts/setup.sh is idempotent and quick when nothing changed).
SHELL := /bin/bash
.DEFAULT_GOAL := help
ENV := . ros2_ws/env.sh &&

.PHONY: help setup demo test bench mutation clean

help:
	@echo "make demo   set up, then drive the simulated HAMR headless; prints a table, writes a plot"
	@echo "make test   set up, then run the whole test suite"
	@echo "make bench  set up, then run the benchmarks (about 8 min); writes docs/benchmarks.md"
	@echo "make mutation  mutation testing of the ROS-free core (long: see docs/testing.md)"
	@echo "make setup  only set up .venv/ and build ros2_ws/"
	@echo "make clean  remove .venv/, ros2_ws/ and out/"

setup:
	@scripts/setup.sh

demo: setup
	@$(ENV) holonomic-demo --robot $(if $(ROBOT),$(ROBOT),hamr) --out out

test: setup
	@$(ENV) python -m pytest tests -q $(PYTEST_ARGS)

bench: setup
	@$(ENV) python bench/run.py $(BENCH_ARGS)

# MUTATION_ARGS: some modules only, e.g. MUTATION_ARGS="limits monitor"
mutation: setup
	@$(ENV) python scripts/mutation.py $(MUTATION_ARGS)

clean:
	rm -rf .venv ros2_ws out .pytest_cache .hypothesis
