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

# Benchmark entry point, first found: `isolab bench`, `python -m benchmarks`, `benchmarks/run.py`.
bench: $(STAMP)
	@if $(VENV)/bin/isolab bench --help >/dev/null 2>&1; then \
		echo "$(VENV)/bin/isolab bench"; $(VENV)/bin/isolab bench; \
	elif [ -f benchmarks/__main__.py ]; then \
		echo "$(PY) -m benchmarks"; $(PY) -m benchmarks; \
	elif [ -f benchmarks/run.py ]; then \
		echo "$(PY) benchmarks/run.py"; $(PY) benchmarks/run.py; \
	else \
		echo "no benchmark entry point: add an 'isolab bench' command or benchmarks/__main__.py" >&2; exit 1; \
	fi

# Load on a real `isolab serve`: 50 clients and a 100,000-case study on loopback; stops within 2 minutes.
load: $(STAMP)
	timeout 150 $(PY) -m benchmarks.load --budget 120

lint: $(STAMP)
	$(VENV)/bin/ruff check engine studies service tests
