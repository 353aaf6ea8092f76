# Two entry points for a fresh machine; each sets itself up (a venv in .venv, torch pinned to the
# CPU wheel) before it runs.
#   make paper   reproduce the paper's Tables II-V      make test   build the docs (strict), run the fast tests
#   make test-all  the docs and every test (slow, statistical, integration too): what CI runs
#   make docs    build the documentation site into site/ (mkdocs.yml); `.venv/bin/mkdocs serve` previews it
VENV   ?= .venv
PYTHON ?= python3
STAMP  := $(VENV)/.installed

.PHONY: setup paper test test-all bench docs
setup: $(STAMP)

$(STAMP): pyproject.toml plugins/idkit-robust/pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install -q --upgrade pip
	$(VENV)/bin/python -m pip install -q torch==2.13.0
	$(VENV)/bin/python -m pip install -q -e ".[test,docs]" -e ./plugins/idkit-robust
	touch $@
	@echo "idkit is installed in $(VENV); to put the idkit command on PATH: . $(VENV)/bin/activate"

# The peers the benchmarks measure (JAX + evosax, pyswarms: ~0.7 GB) only when benchmarking.
BENCH_STAMP := $(VENV)/.bench-installed
$(BENCH_STAMP): $(STAMP)
	$(VENV)/bin/python -m pip install -q -e ".[bench]"
	touch $@

paper: $(STAMP)
	$(VENV)/bin/idkit +experiment=paper

# The docs build first: a broken page or docstring fails CI (`.ci/run` is `make test-all`).
test: docs
	$(VENV)/bin/pytest

test-all: docs
	$(VENV)/bin/pytest -m ""

# Not --quiet: it keeps griffe's docstring warnings from failing the strict build. The variable
# only hides mkdocs-material's end-of-life banner.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

bench: $(BENCH_STAMP)
	$(VENV)/bin/python bench/estimators.py
	$(VENV)/bin/python bench/rnea.py
