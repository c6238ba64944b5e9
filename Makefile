# Two entry points, both set up .venv/ from nothing: `make demo` and `make test`.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
VPY := $(VENV)/bin/python
CLI := $(VENV)/bin/gyro-thermal-comp
# Keep DDS on this machine, on a domain of our own (tests set their own too).
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export ROS_DOMAIN_ID ?= 42
export AMENT_PREFIX_PATH := $(abspath $(VENV))
export MPLBACKEND := Agg

.PHONY: demo test venv clean-venv bags test-under-load

$(VENV)/.created:
	@$(PYTHON) -c 'import sys; assert sys.version_info[:2] >= (3, 11), "need Python 3.11 (the ROS 2 Jazzy wheels are built for it)"'
	$(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --upgrade pip
	touch $@

$(VENV)/.runtime: $(VENV)/.created requirements.txt requirements-robot.txt requirements-tools.txt setup.py setup.cfg package.xml
	$(VPY) -m pip install --quiet -r requirements.txt
	$(VPY) -m pip install --quiet --no-deps -e .
	touch $@

$(VENV)/.test: $(VENV)/.runtime requirements-test.txt
	$(VPY) -m pip install --quiet -r requirements-test.txt
	touch $@

venv: $(VENV)/.test

demo: $(VENV)/.runtime
	$(CLI) demo bags

test: $(VENV)/.test
	$(VPY) -m pytest -q -n 2 --dist loadfile test

# Regenerate the bundled bags from the commands in bags/manifest.json (value-for-value identical).
bags: $(VENV)/.runtime
	$(CLI) bundle bags --force

clean-venv:
	rm -rf $(VENV)

# `make test` 3x in a fresh clone with every core busy: the suite must pass under load (docs/testing.md).
test-under-load:
	tools/test-under-load
