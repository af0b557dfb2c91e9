# Quick start: `make demo` runs the phantom scene end to end; `make test` runs the test suite;
# `make docs` builds the user guide and API reference (warnings are errors) into docs/_build/html.
# `make lint` checks style and types (ruff check, ruff format --check, mypy).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.installed-docs

.PHONY: demo test docs lint bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

$(DOCS_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,docs]"
	touch $(DOCS_STAMP)

demo: $(STAMP)
	$(BIN)/harpx demo --output harpx-demo

# one worker per core, at most 4 (each builds the shared scene fixtures it needs), idle
# workers taking queued tests from busy ones (pytest-xdist). `pytest -n 0`: one process.
test: $(STAMP)
	$(BIN)/python -m pytest -q -n auto --maxprocesses 4 --dist worksteal

# the tutorials are rendered, not run (the tests run them); the build takes ~10 s of CPU
docs: $(DOCS_STAMP)
	rm -rf docs/_build
	$(BIN)/python -m sphinx -W --keep-going -q -b html docs docs/_build/html
	@echo "user guide: docs/_build/html/index.html"
lint: $(STAMP)
	$(BIN)/ruff check harpx tests benchmarks tutorials conftest.py
	$(BIN)/ruff format --check harpx tests benchmarks tutorials conftest.py
	$(BIN)/mypy harpx

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_phase.py
	$(BIN)/python benchmarks/bench_mechanics.py

clean:
	rm -rf $(VENV) harpx-demo docs/_build
