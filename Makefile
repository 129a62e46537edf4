# mech_balance: `make run` runs the main job, `make test` runs every test.
# Both create .venv on first use and re-use it afterwards; `make help` lists the targets.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# Touched once requirements and the package are installed; lives in .venv, so removing
# .venv also forgets it.
STAMP := $(VENV)/.mech_balance-installed
# Touched once the optional test dependencies (requirements-test.txt: MuJoCo) are installed.
TEST_STAMP := $(VENV)/.mech_balance-test-installed
PIP := $(BIN)/python -m pip --disable-pip-version-check

.DEFAULT_GOAL := help
.PHONY: help venv run test bench bench-mujoco clean

help:  ## List the targets.
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | sed -e 's/:.*## /\t/' | expand -t 8

venv: $(STAMP)  ## Create .venv with the pinned requirements and the package (editable).

# --use-pep517 makes the editable install a PEP 660 wheel, so pip puts the console scripts
# (mech-balance, rig_node) in .venv/bin whatever setup.cfg says for `setup.py develop`.
# --no-build-isolation builds with the pinned setuptools/wheel already in .venv.
$(STAMP): requirements.txt setup.py
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet -r requirements.txt
	$(PIP) install --quiet --no-deps --no-build-isolation --use-pep517 -e .
	touch $@

# The main job: the analysis table of the default scene, an original-vs-balanced recording,
# then the rig node on the default scene (it says what it publishes; Ctrl-C stops it).
run: export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
run: venv  ## Install everything and run the main job.
	$(BIN)/mech-balance analyze --scene hoeken
	$(BIN)/mech-balance record --scene hoeken --balance --out recordings/hoeken.rrd
	$(BIN)/rig_node --ros-args --params-file config/rig_params.yaml

# The optional test dependencies go in after the pinned environment (they share numpy).
$(TEST_STAMP): requirements-test.txt $(STAMP)
	$(PIP) install --quiet -r requirements-test.txt
	touch $@

# The suite runs on TEST_WORKERS processes (pytest-xdist), each module whole on one worker
# (its module-scoped fixtures built once), the longest modules first: test/conftest.py
# orders them, `--no-loadscope-reorder` keeps that order (README "Tests").
TEST_WORKERS ?= 2
test: export ROS_AUTOMATIC_DISCOVERY_RANGE = LOCALHOST
test: $(TEST_STAMP)  ## Install everything (MuJoCo too) and run all tests (flake8, pep257, colcon, suite).
	$(BIN)/python -m pytest test -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder

bench: venv  ## Print the timing tables (core, balancing, recording, node).
	$(BIN)/mech-balance bench

# MuJoCo is an optional dependency of the tests and this benchmark (requirements-test.txt).
bench-mujoco: $(TEST_STAMP)  ## Install MuJoCo (optional, pinned) and compare it with this package.
	$(BIN)/mech-balance bench --compare mujoco

clean:  ## Remove .venv and build leftovers.
	rm -rf $(VENV) build install log .pytest_cache *.egg-info
