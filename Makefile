# Everything runs inside .venv, created on first use from the machine's Python >= 3.10.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: drop-test test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

# Quick start 1: a simulated drop test from -5 deg at 0 A and 1 A with the default config.
drop-test: $(STAMP)
	$(BIN)/sashil drop-test --current 0 --current 1 --out runs/quickstart-drop-test

# Quick start 2: the whole test suite (no hardware needed).
test: $(STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/python tools/bench_sim.py

clean:
	rm -rf $(VENV) build src/*.egg-info
