# Set-up and every routine job. Each target installs what it needs into .venv, idempotently.
SHELL := /bin/bash
.DEFAULT_GOAL := help

PYTHON ?= python3
VENV ?= .venv
STAMP := $(VENV)/.setup-done
# Every command below runs with the ROS 2 environment set once, in a fixed order.
RUN := source tools/ros_env.sh $(VENV) &&
PYTEST_ARGS ?=
# pytest-xdist workers (each test module runs whole on one worker: its fixtures and ROS domain stay its own);
# 0 runs the suite in this process
TEST_WORKERS ?= 2
PYTEST := python -m pytest -n $(TEST_WORKERS) --dist loadfile
DEMO_OUT ?= out/demo
BENCH_ARGS ?=

.PHONY: help setup test test-fast demo bench bench-peers clean-venv

help:
	@echo "make demo   - set up .venv and run the pipeline end to end (report under $(DEMO_OUT))"
	@echo "make test   - set up .venv and run the whole test suite"
	@echo "make bench  - set up .venv and run the benchmarks (results under bench/)"
	@echo "make setup  - only build .venv (ROS 2 Jazzy wheels from PyPI, Python deps, the package)"

setup: $(STAMP)

$(STAMP): requirements.txt requirements-ros.txt requirements-test.txt setup.py setup.cfg package.xml tools/ros_env.sh
	@test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -r requirements-ros.txt -r requirements.txt -r requirements-test.txt
	$(VENV)/bin/python -m pip install --quiet --no-deps -e .
	@# What colcon would install into share/: the ament index marker, package.xml and config/, so
	@# that ament_index_python finds the package in the venv exactly as after `colcon build`.
	mkdir -p $(VENV)/share/ament_index/resource_index/packages $(VENV)/share/aircraft_docking_tracker
	touch $(VENV)/share/ament_index/resource_index/packages/aircraft_docking_tracker
	ln -sfn $(CURDIR)/config $(VENV)/share/aircraft_docking_tracker/config
	ln -sfn $(CURDIR)/package.xml $(VENV)/share/aircraft_docking_tracker/package.xml
	@grep -q "tools/ros_env.sh" $(VENV)/bin/activate || \
	  echo "source \"$(CURDIR)/tools/ros_env.sh\" \"$(abspath $(VENV))\"" >> $(VENV)/bin/activate
	$(RUN) python -c "import rclpy, cv2, mcap, numpy; print('setup ok: rclpy, OpenCV', cv2.__version__)"
	@touch $(STAMP)

test: setup
	$(RUN) $(PYTEST) $(PYTEST_ARGS)

test-fast: setup
	$(RUN) $(PYTEST) -m "not slow" $(PYTEST_ARGS)

demo: setup
	$(RUN) python tools/demo.py --out $(DEMO_OUT)

bench: setup
	$(RUN) python bench/run_all.py $(BENCH_ARGS)

clean-venv:
	rm -rf $(VENV)
