# Two commands set everything up on a fresh machine: `make test` and `make demo`.
# `install` is idempotent: it re-runs pip only when pyproject.toml or setup.py changes.
SHELL := /bin/bash
PYTHON ?= python3.11
VENV := .venv
STAMP := $(VENV)/.installed
BIN := $(VENV)/bin

.PHONY: install test test-fast demo bench system-deps clean

install: system-deps $(STAMP)

# open3d links libusb-1.0; Drake's headless VTK renderer needs Mesa's EGL vendor library.
system-deps:
	@missing=""; \
	for lib in libusb-1.0.so.0 libEGL.so.1 libEGL_mesa.so.0; do \
	  ldconfig -p | grep -q "$$lib" || missing="$$missing $$lib"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages for:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq libusb-1.0-0 libegl1 libegl-mesa0 libgl1-mesa-dri; \
	fi

$(STAMP): pyproject.toml setup.py
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	# CPU torch first, so that no dependency resolution can reach for a CUDA build.
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[dev]'
	touch $(STAMP)

# Every test, the slow ones included (what CI runs: .ci/run).
test: install
	$(BIN)/python -m pytest -q

# The quick loop while editing: skips the tests marked slow (the demo, notebooks 02-03, a
# procedural library, training subprocesses, the fresh non-editable install).
test-fast: install
	$(BIN)/python -m pytest -q -m "not slow"

demo: install
	$(BIN)/corn-drake demo

bench: install
	mkdir -p reports
	$(BIN)/corn-drake bench sim --report reports/bench_sim.json

clean:
	rm -rf $(VENV) build *.egg-info
