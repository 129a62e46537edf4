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
# pip prints each package as it collects and installs it (the first install fills .venv with
# about 1.3 GB and takes a few minutes).
$(STAMP): requirements.txt setup.py
	@echo '== creating $(VENV) and installing the pinned requirements (first time: a few minutes)'
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(PIP) install --progress-bar on -r requirements.txt
	@echo '== installing mech_balance (editable) into $(VENV)'
	$(PIP) install --progress-bar on --no-deps --no-build-isolation --use-pep517 -e .
	touch $@
	@echo '== $(VENV) is ready'

# The main job: the analysis table of the default scene, an original-vs-balanced recording,
# then the rig node on the default scene (it logs what it publishes; the line printed before
# it says that Ctrl-C stops it).
run: export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
run: venv  ## Install everything and run the main job.
	@echo "== 1/3 the shaking of Hoeken's four-bar over one revolution"
	$(BIN)/mech-balance analyze --scene hoeken
	@echo '== 2/3 an original-vs-balanced recording (open it with: rerun recordings/hoeken.rrd)'
	$(BIN)/mech-balance record --scene hoeken --balance --out recordings/hoeken.rrd
	@echo '== 3/3 the rig node on hoeken, publishing until you press Ctrl-C'
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
