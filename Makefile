# Two entry points for a fresh machine; each sets itself up (a venv in .venv, torch pinned to the
# CPU build, every other package at the version in constraints.txt) before it runs.
#   make paper     reproduce the paper's Tables II-V     make test   lint, type-check, build the docs (strict), run the fast tests
#   make test-all  lint, types, the docs and every test (slow, statistical, integration too): what CI runs
#   make docs      build the documentation site into site/ (mkdocs.yml); `.venv/bin/mkdocs serve` previews it
#   make lock      re-resolve every dependency to its newest release, run the whole suite on it, and
#                  rewrite constraints.txt only if it passes (the scheduled check for dependency drift)
VENV   ?= .venv
PYTHON ?= python3
STAMP  := $(VENV)/.installed
EXTRAS := test,docs,mjcf,logs,collision
# pyproject.toml keeps ranges for users' environments; set-up and CI install the locked versions.
PIP    := $(VENV)/bin/python -m pip install -q -c constraints.txt

.PHONY: setup paper test test-all bench docs lint typecheck lock
setup: $(STAMP)

# torch first, on its own: its CPU build where PyTorch's CPU index is reachable (.ci/torch-index);
# pip would otherwise take the multi-GB CUDA build of an ordinary Linux machine.
$(STAMP): pyproject.toml plugins/idkit-robust/pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PIP) --upgrade pip
	$(PIP) torch==2.13.0 $$($(PYTHON) .ci/torch-index)
	$(PIP) -e ".[$(EXTRAS)]" -e ./plugins/idkit-robust
	touch $@
	@echo "idkit is installed in $(VENV); to put the idkit command on PATH: . $(VENV)/bin/activate"

# The peers the benchmarks measure (JAX + evosax, pyswarms, FIGAROH and its solvers) only when benchmarking,
# at the versions in constraints.txt where it has them.
BENCH_STAMP := $(VENV)/.bench-installed
$(BENCH_STAMP): $(STAMP)
	$(PIP) -e ".[bench]"
	touch $@

paper: $(STAMP)
	$(VENV)/bin/idkit +experiment=paper

lint: $(STAMP)
	$(VENV)/bin/ruff check .

# mypy on idkit/ ([tool.mypy] in pyproject.toml says what and how strictly)
typecheck: $(STAMP)
	$(VENV)/bin/mypy

# Lint, types and the docs first: a lint finding, a type error, a broken page or docstring fails CI
# (`.ci/run` is `make test-all`).
test: lint typecheck docs
	$(VENV)/bin/pytest

test-all: lint typecheck docs
	$(VENV)/bin/pytest -m ""

# Not --quiet: it keeps griffe's docstring warnings from failing the strict build. The variable
# only hides mkdocs-material's end-of-life banner.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

bench: $(BENCH_STAMP)
	$(VENV)/bin/python bench/estimators.py
	$(VENV)/bin/python bench/rnea.py
	$(VENV)/bin/python bench/pcls_figaroh.py
	$(VENV)/bin/python bench/pcls_command.py

lock:
	PYTHON=$(PYTHON) .ci/lock $(EXTRAS)
