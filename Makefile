# vd — two commands for a fresh clone: `make demo` and `make test`.
# Every target sets the workspace up first if needed (idempotent, seconds when nothing changed).
SHELL := /bin/bash
.SHELLFLAGS := -e -o pipefail -c
RUN := . ./env.sh &&

.PHONY: setup build demo test test-all pytest lint typecheck format bench clean help

help:
	@echo 'make demo   set up if needed, run the simulator/observer/estimator graph, report'
	@echo 'make test   set up if needed, lint, type-check and run the tests (long end-to-end runs: CI)'
	@echo 'make test-all  the same with the long end-to-end runs (what CI runs)'
	@echo 'make bench  benchmarks and accuracy evaluations (print figures)'
	@echo 'make setup  only the set-up (.venv, ROS 2, colcon build, env.sh)'

setup:
	@bash scripts/setup_workspace.sh

build: setup

demo: setup
	$(RUN) python scripts/demo.py $(DEMO_ARGS)

test: setup lint typecheck pytest

# every test, the long end-to-end runs (marked slow) included: what CI runs (.ci/run)
test-all:
	VD_TEST_ALL=1 $(MAKE) test

pytest: setup
	$(RUN) python -m pytest $(PYTEST_ARGS)

lint: setup
	$(RUN) ruff check src tests scripts && ruff format --check src tests scripts

format: setup
	$(RUN) ruff format src tests scripts && ruff check --fix src tests scripts

# mypy --strict on the Python packages, nodes included: the settings are in pyproject.toml
typecheck: setup
	@echo 'mypy --strict (pyproject.toml: vd_common, vd_sim_node, vd_observer_node)'
	@$(RUN) mypy

# the peers compared in bench_peers.py (opensmc, commonroad-vehicle-models) are bench-only
bench: setup
	$(RUN) pip install --quiet -r requirements/bench.in -c requirements/lock-kilted-py311.txt
	$(RUN) for s in scripts/bench_*.py scripts/eval_*.py scripts/check_*.py; do \
	  [ -f "$$s" ] || continue; echo "=== $$s"; python "$$s"; done

clean:
	rm -rf build install log env.sh
