# CARLOS — set-up on a fresh machine: `make demo` (runs the data-generation example) and `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SYSTEM_PACKAGES := libusb-1.0-0 libgl1 libegl1 libx11-6 libxext6 libxrender1
NPROC := $(shell nproc 2>/dev/null || echo 2)

.PHONY: install system-packages demo test test-slow lint typecheck bench crds clean

install: $(STAMP)

system-packages:
	@missing=""; for p in $(SYSTEM_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then echo "installing system packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; \
	  else echo "missing system packages:$$missing (run: sudo apt-get install$$missing)"; exit 1; fi; \
	fi

$(STAMP): pyproject.toml
	@$(MAKE) --no-print-directory system-packages
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	touch $(STAMP)

demo: install
	$(VENV)/bin/carlos run examples/runs/data-generation.yaml --output file://./results

test: install
	$(PY) -m pytest -n $(NPROC) -m "not slow and not e2e" tests

test-slow: install
	$(PY) -m pytest -m slow tests

lint: install
	$(VENV)/bin/ruff check simcore operator tests bench
	$(VENV)/bin/ruff format --check simcore operator tests bench

typecheck: install
	$(VENV)/bin/mypy

bench: install
	$(PY) bench/simcore.py

# the SimulationRun CRD from simcore/spec.py, for kubectl and for the Helm chart (tests/test_crd.py checks drift)
crds: install
	mkdir -p crds helm/carlos/crds
	$(VENV)/bin/carlos crds > crds/simulationrun.yaml
	cp crds/simulationrun.yaml helm/carlos/crds/simulationrun.yaml

clean:
	rm -rf $(VENV) results .pytest_cache .mypy_cache .ruff_cache
