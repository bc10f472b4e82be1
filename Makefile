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

.PHONY: venv test demo bench clean-venv

venv: $(STAMP)

$(STAMP): setup.py setup.cfg package.xml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@# compile the numba kernels now (numba's on-disk cache), not while the first run waits at "ready";
	@# not fatal: without it they compile at first use
	$(VENV)/bin/isa-mocap warmup || echo "make venv: warm-up failed; the kernels compile at first use instead"
	@touch $(STAMP)

test: venv
	$(PY) -m pytest -n 2 --timeout 600 $(PYTEST_ARGS)

demo: venv
	$(VENV)/bin/isa-mocap run --lockstep --out out/demo

bench: venv
	$(VENV)/bin/isa-mocap bench all

clean-venv:
	rm -rf $(VENV)
