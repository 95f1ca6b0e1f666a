# Two commands set everything up on a fresh machine: `make test` and `make demo`.
# `install` is idempotent: it re-runs pip only when pyproject.toml or setup.py changes.
SHELL := /bin/bash
# Python 3.11 where it runs: pip installs the 192 MB CPU torch wheel for it here. 3.12 (Ubuntu
# 24.04's python3) and 3.13 are the fallbacks, in that order; `make test-py312` and `make
# test-py313` check them: there pip takes torch from PyPI, the CUDA build, ~2.7 GB of wheels and
# a 6.6 GB venv (measured on 3.12). A pyenv shim exists for every installed version but fails
# for one not selected, so each is asked to run. docs/install.md: what runs where.
PYTHON ?= $(shell for p in python3.11 python3.12 python3.13; do $$p -c '' >/dev/null 2>&1 && { echo $$p; break; }; done)
# TORCH_INDEX=URL: take torch from that index, e.g. PyTorch's own CPU wheel index (docs/install.md),
# where the machine reaches it: the ~200 MB CPU build instead of PyPI's Linux CUDA build (~2.7 GB).
# Empty (the default): torch from pip's configured index, PyPI by default.
TORCH_INDEX ?=
TORCH_FROM := $(if $(TORCH_INDEX),--index-url $(TORCH_INDEX),)
VENV := .venv
STAMP := $(VENV)/.installed
BIN := $(VENV)/bin

.PHONY: install test test-fast notebooks demo bench system-deps clean

install: system-deps $(STAMP)

# open3d links libusb-1.0; Drake's headless VTK renderer needs Mesa's EGL vendor library; the
# browser test opens a recording in Chromium (tests/test_browser_recording.py), ~1 minute to
# install the first time.
system-deps:
	@missing=""; \
	for lib in libusb-1.0.so.0 libEGL.so.1 libEGL_mesa.so.0; do \
	  ldconfig -p | grep -q "$$lib" || missing="$$missing $$lib"; \
	done; \
	command -v chromium >/dev/null || missing="$$missing chromium"; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages for:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq libusb-1.0-0 libegl1 libegl-mesa0 libgl1-mesa-dri chromium; \
	fi

$(STAMP): pyproject.toml setup.py
	@test -x $(BIN)/python || test -n "$(PYTHON)" || { echo "no python3.11, python3.12 or \
	python3.13 runs here; name one: make PYTHON=/path/to/python3.13" >&2; exit 1; }
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	# CPU torch first, so that no dependency resolution can reach for a CUDA build.
	$(BIN)/pip install -q $(TORCH_FROM) torch==2.13.0
	$(BIN)/pip install -q -e '.[dev]'
	touch $(STAMP)

# Every test, the slow ones included (what CI runs: .ci/run); the 20 slowest are listed at the
# end (docs/results/test_suite.md: what the suite costs and where).
test: install
	$(BIN)/python -m pytest -q --durations=20

# The quick loop while editing: skips the tests marked slow (the demo, notebooks 02-03, a
# procedural library, training subprocesses, the fresh non-editable install).
test-fast: install
	$(BIN)/python -m pytest -q -m "not slow"

# The other supported Pythons beside the default venv: `make test-py312` / `make test-py313`
# make .venv312 / .venv313 with pyenv's 3.12.1 / 3.13.0 (PYTHON312=... / PYTHON313=... name
# others), install as `install` does, then run the fast tests. Slow the first time: torch for
# 3.12 and 3.13 is the CUDA build from PyPI (see PYTHON above).
PYTHON312 ?= env PYENV_VERSION=3.12.1 python3.12
PYTHON313 ?= env PYENV_VERSION=3.13.0 python3.13

.PRECIOUS: .venv%/.installed  # the stamp of a finished install: make must not delete it
.venv%/.installed: pyproject.toml setup.py
	@test -x .venv$*/bin/python || $(PYTHON$*) -m venv .venv$*
	.venv$*/bin/pip install -q --upgrade pip
	.venv$*/bin/pip install -q $(TORCH_FROM) torch==2.13.0
	.venv$*/bin/pip install -q -e '.[dev]'
	touch $@

test-py%: system-deps .venv%/.installed
	.venv$*/bin/python -m pytest -q -m "not slow"

# JupyterLab on notebooks/ (the dev extras install it); the tests run them headless instead.
notebooks: install
	$(BIN)/jupyter lab notebooks/

demo: install
	$(BIN)/corn-drake demo

bench: install
	mkdir -p reports
	$(BIN)/corn-drake bench sim --report reports/bench_sim.json

clean:
	rm -rf $(VENV) .venv312 .venv313 build *.egg-info
