# suspension_tuning: the two commands a user needs on a fresh machine are
#   make demo    (sets everything up, then runs the main job)
#   make test    (sets everything up, then runs ruff, the test suite and the example project)
# `make setup` is idempotent: stamps in .stamps/ make it take seconds when nothing changed.

SHELL := /bin/bash
.SHELLFLAGS := -eo pipefail -c

PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMPS := .stamps

# DDS discovery stays on loopback (multicast on the real network is forbidden here);
# each run may pick its own domain.  The test session picks its own in test/conftest.py.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID ?= 42
export RMW_IMPLEMENTATION := rmw_fastrtps_cpp
export AMENT_PREFIX_PATH := $(abspath $(VENV))

INTERFACE_FILES := $(shell find suspension_tuning_interfaces -type f)
PIP_QUIET := 2>&1 | { grep -v -e 'is ignored: it is neither' -e '^$$' || true; }

.PHONY: setup test lint demo bench study sample-bag clean

setup: $(STAMPS)/package $(STAMPS)/npm

$(STAMPS)/venv:
	@mkdir -p $(STAMPS)
	$(PYTHON) -m venv $(VENV)
	@touch $@

$(STAMPS)/requirements: requirements.txt $(STAMPS)/venv
	$(PY) -m pip install -q -r requirements.txt $(PIP_QUIET)
	@touch $@

$(STAMPS)/interfaces: $(STAMPS)/requirements $(INTERFACE_FILES) scripts/build_interfaces.sh
	scripts/build_interfaces.sh $(VENV) build/interfaces
	@touch $@

$(STAMPS)/package: $(STAMPS)/interfaces setup.py setup.cfg package.xml resource/suspension_tuning \
		$(wildcard config/*.yaml) $(wildcard config/*.json) $(wildcard config/roads/*) scripts/install_ament_files.py
	$(PY) -m pip install -q --no-deps --no-build-isolation -e . $(PIP_QUIET)
	$(PY) scripts/install_ament_files.py $(VENV)
	@touch $@

# The method study's extra (requirements-study.txt: the peer optimisers it compares with
# the paper's method); the product does not need it, so `make setup` leaves it out.
$(STAMPS)/study-extra: requirements-study.txt $(STAMPS)/requirements
	$(PY) -m pip install -q -r requirements-study.txt $(PIP_QUIET)
	@touch $@

# The upstream ros2 command line (ros2cli is not on PyPI), installed from the shared
# tools beside the clone into build/ros2cli, outside the venv:
#   PYTHONPATH=build/ros2cli build/ros2cli/bin/ros2 node list
# test/test_ros2_cli.py uses it (and installs its own when it is absent).  Without the
# shared tools the ros2 tests skip and say why.
ROS2CLI_INSTALL := ../shared/tools/ros2cli/install.sh
$(STAMPS)/ros2cli: $(STAMPS)/requirements
	@if [ -f $(ROS2CLI_INSTALL) ]; then \
		bash $(ROS2CLI_INSTALL) build/ros2cli $(abspath $(PY)) $(PIP_QUIET); \
	else \
		echo "$(ROS2CLI_INSTALL) not found: the ros2 command-line tests will be skipped"; \
	fi
	@touch $@

# Foxglove's own decoding libraries (pinned in tools/foxglove/package-lock.json), installed
# into tools/foxglove/node_modules: the tests decode recorded bags with them.  Without
# npm on the machine those tests skip and say why.
$(STAMPS)/npm: tools/foxglove/package.json tools/foxglove/package-lock.json
	@mkdir -p $(STAMPS)
	@if command -v npm >/dev/null; then \
		npm ci --prefix tools/foxglove --no-audit --no-fund --loglevel=error; \
	else \
		echo "npm not found: the Foxglove decoding tests will be skipped"; \
	fi
	@touch $@

lint: setup
	$(VENV)/bin/ruff check .

# The example project runs from its own folder, against the installed package and
# the testing kit's pytest plugin, as a user's project would.
test: lint $(STAMPS)/study-extra $(STAMPS)/ros2cli
	$(PY) -m pytest -n 2 --dist loadfile --no-loadscope-reorder test
	cd examples/custom_valve_controller && $(abspath $(PY)) -m pytest -n 2

demo: setup
	$(PY) -m suspension_tuning.demo

study: setup $(STAMPS)/study-extra
	$(PY) -m suspension_tuning.study --out out/study --docs-dir docs/img

bench: setup $(STAMPS)/study-extra
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b; done

# bags/sample: the ride run of make demo, recorded again (after a change of the model,
# the road or the bag layout), checked with Foxglove's decoder where node is installed.
sample-bag: setup
	$(PY) scripts/regenerate_sample_bag.py

clean:
	rm -rf $(VENV) $(STAMPS) build *.egg-info tools/foxglove/node_modules
