# Two entry points for a fresh machine; each sets itself up (a venv in .venv, torch pinned to the
# CPU wheel) before it runs.
#   make paper   reproduce the paper's Tables II-V      make test   run the fast tests
#   make test-all  every test (slow, statistical, integration too): what CI runs
VENV   ?= .venv
PYTHON ?= python3
STAMP  := $(VENV)/.installed

.PHONY: setup paper test test-all bench
setup: $(STAMP)

$(STAMP): pyproject.toml plugins/idkit-robust/pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install -q --upgrade pip
	$(VENV)/bin/python -m pip install -q torch==2.13.0
	$(VENV)/bin/python -m pip install -q -e ".[test,bench]" -e ./plugins/idkit-robust
	touch $@

paper: $(STAMP)
	$(VENV)/bin/idkit +experiment=paper

test: $(STAMP)
	$(VENV)/bin/pytest

test-all: $(STAMP)
	$(VENV)/bin/pytest -m ""

bench: $(STAMP)
	$(VENV)/bin/python bench/estimators.py
	$(VENV)/bin/python bench/rnea.py
