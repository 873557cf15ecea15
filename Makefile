# isolab developer contract: `make serve` and `make test` work on a fresh machine with Python 3.11.
# The virtualenv is (re)installed only when pyproject.toml changes; code edits need no reinstall.

PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

HOST ?= 127.0.0.1
PORT ?= 8000
WORKERS ?= 2
DATA ?= ./data

.PHONY: install serve test bench load lint

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -e '.[test]'
	touch $@

serve: $(STAMP)
	$(VENV)/bin/isolab serve --host $(HOST) --port $(PORT) --workers $(WORKERS) --data $(DATA)

test: $(STAMP)
	$(PY) -m pytest -q

# The performance figures (docs/performance.md): the engine on one core against a numpy loop and solve_ivp,
# then 10,000- and 100,000-case studies through a real `isolab serve` (about 15 minutes on an idle machine).
bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m benchmarks kernels
	$(PY) -m benchmarks endtoend

# Load on a real `isolab serve`: 50 clients and a 100,000-case study on loopback; stops within 2 minutes.
load: $(STAMP)
	timeout 150 $(PY) -m benchmarks.load --budget 120

lint: $(STAMP)
	$(VENV)/bin/ruff check engine studies service tests
