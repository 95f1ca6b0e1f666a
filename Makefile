# Two commands set everything up on a fresh machine: `make test` and `make demo`.
# `install` is idempotent: it re-runs pip only when pyproject.toml or setup.py changes.
SHELL := /bin/bash
# Python 3.11 where it runs: pip installs the 192 MB CPU torch wheel for it here. 3.12 is the
# fallback (Ubuntu 24.04's python3) and `make test-py312` checks it: there pip takes torch from
# PyPI, the CUDA build, ~2.7 GB of wheels and a 6.6 GB venv (measured). A pyenv shim exists for
# every installed version but fails for one not selected, so each is asked to run.
PYTHON ?= $(shell for p in python3.11 python3.12; do $$p -c '' >/dev/null 2>&1 && { echo $$p; break; }; done)
VENV := .venv
STAMP := $(VENV)/.installed
BIN := $(VENV)/bin

.PHONY: install test test-fast test-py312 demo bench system-deps clean

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
	@test -x $(BIN)/python || test -n "$(PYTHON)" || { echo "no python3.11 or python3.12 runs \
	here; name one: make PYTHON=/path/to/python3.12" >&2; exit 1; }
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

# The other supported Python beside the default venv: .venv312 made by python3.12 (pyenv's
# 3.12.1 where pyenv is used; PYTHON312=... names another), installed as `install` does, then
# the fast tests. Slow the first time: torch for 3.12 is the CUDA build (see PYTHON above).
PYTHON312 ?= env PYENV_VERSION=3.12.1 python3.12
VENV312 := .venv312
STAMP312 := $(VENV312)/.installed

$(STAMP312): pyproject.toml setup.py
	@test -x $(VENV312)/bin/python || $(PYTHON312) -m venv $(VENV312)
	$(VENV312)/bin/pip install -q --upgrade pip
	$(VENV312)/bin/pip install -q torch==2.13.0
	$(VENV312)/bin/pip install -q -e '.[dev]'
	touch $(STAMP312)

test-py312: system-deps $(STAMP312)
	$(VENV312)/bin/python -m pytest -q -m "not slow"

demo: install
	$(BIN)/corn-drake demo

bench: install
	mkdir -p reports
	$(BIN)/corn-drake bench sim --report reports/bench_sim.json

clean:
	rm -rf $(VENV) $(VENV312) build *.egg-info
