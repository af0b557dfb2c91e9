# Quick start: `make demo` runs the phantom scene end to end; `make test` runs the test suite;
# `make lint` checks style and types (ruff check, ruff format --check, mypy).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/harpx demo --output harpx-demo

test: $(STAMP)
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check harpx tests benchmarks tutorials conftest.py
	$(BIN)/ruff format --check harpx tests benchmarks tutorials conftest.py
	$(BIN)/mypy harpx

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_phase.py
	$(BIN)/python benchmarks/bench_mechanics.py

clean:
	rm -rf $(VENV) harpx-demo
