# isolab developer contract: `make serve` and `make test` work on a fresh machine with Python 3.11.
# The virtualenv is (re)installed only when pyproject.toml changes; code edits need no reinstall.

PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test
CODE := engine studies service tests benchmarks

# The compiled kernels live in one folder per machine and engine version, which isolab.engine chooses
# itself (`isolab.engine.kernel_cache_folder()`: ~/.cache/isolab/numba/<hash of the engine's sources>, or
# NUMBA_CACHE_DIR when set): numba notices an edit only in a kernel's own file, and the kernels inline code
# from each other's modules, so the hash starts a fresh cache after any engine edit. The make targets, the
# command line run by hand and the service's Dask workers all share it.

HOST ?= 127.0.0.1
PORT ?= 8000
WORKERS ?= 2
DATA ?= ./data

.PHONY: install serve test test-fast bench load lint typecheck format browser docs

install: $(STAMP)

# the service and the benchmarks need isolab alone; the tests, lint and type checks also its test extra
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -e .
	touch $@

$(TEST_STAMP): $(STAMP)
	$(PY) -m pip install -e '.[test]'
	touch $@

# The address clients reach the service at (a wildcard host on loopback): `make serve` prints it as the
# ISOLAB_URL the CLI (`isolab submit/status/fetch/sensitivity`) and the Python client read.
URL_HOST = $(if $(filter 0.0.0.0 ::,$(HOST)),127.0.0.1,$(if $(findstring :,$(HOST)),[$(HOST)],$(HOST)))

serve: $(STAMP)
	@echo "isolab: the CLI and the Python client reach this service with (in another shell):"
	@echo "  export ISOLAB_URL=http://$(URL_HOST):$(PORT)"
	$(VENV)/bin/isolab serve --host $(HOST) --port $(PORT) --workers $(WORKERS) --data $(DATA)

# docs/study-files.md, the reference of study and scene files, made from the models (a test fails while it
# is not what they give: run this after changing a model of studies/inputs/schema/ or studies/inputs/study.py).
docs: $(STAMP)
	$(PY) -m isolab.studies.authoring.file_reference > docs/study-files.md.part
	mv docs/study-files.md.part docs/study-files.md

# The whole suite in 3 test processes on 2 cores (pytest-xdist; a test file stays in one process, so its
# module fixtures, services among them, start once): many tests wait on a service, a subprocess or a
# browser, and a third process fills those waits (warm: 3 min 58 s against 4 min 24 s with 2; 4 min 48 s
# with 4, where the contention costs more than the waits). All use the one kernel cache of the machine
# (above), and keep Python's bytecode caches (__pycache__, ignored by git) even where the environment
# turns them off: without them every run compiles and rewrites the assertions of ~470 modules again in
# each test process (about 5 s of CPU each).
TEST_PROCESSES ?= 3
test: $(TEST_STAMP)
	PYTHONDONTWRITEBYTECODE= $(PY) -m pytest -q -n $(TEST_PROCESSES) --dist loadfile

# Everything not marked slow (services in subprocesses, fault injection, the wheel build, memory measured
# in processes of their own): under a minute on 2 cores, in 2 processes (CPU-bound: 3 gain nothing).
# tests/conftest.py gives each test process one BLAS thread (with the libraries' default, a thread per
# core in each process, some tests ran 20x slower).
FAST_PROCESSES ?= 2
test-fast: $(TEST_STAMP)
	PYTHONDONTWRITEBYTECODE= $(PY) -m pytest -q -n $(FAST_PROCESSES) --dist loadfile -m "not slow"

# The performance figures (docs/performance.md): the engine on one core against a numpy loop and solve_ivp,
# then 10,000- and 100,000-case studies through a real `isolab serve` (about 15 minutes on an idle machine).
bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m benchmarks kernels
	$(PY) -m benchmarks endtoend
	$(PY) -m benchmarks million
	$(PY) -m benchmarks startup

# Load on a real `isolab serve`: 50 clients and a 100,000-case study on loopback; stops within 2 minutes.
load: $(STAMP)
	timeout 150 $(PY) -m benchmarks.load --budget 120

lint: $(TEST_STAMP)
	$(VENV)/bin/ruff check $(CODE)
	$(VENV)/bin/ruff format --check $(CODE)
	$(MAKE) --no-print-directory typecheck

format: $(TEST_STAMP)
	$(VENV)/bin/ruff check --fix $(CODE)
	$(VENV)/bin/ruff format $(CODE)

# mypy on isolab.engine, isolab.studies and isolab.service. The folders install under the isolab namespace through
# setuptools' package-dir mapping, which mypy cannot follow, so it reads them through a view of links
# laid out as installed (.typecheck/isolab/{engine,studies,service}).
typecheck: $(TEST_STAMP)
	mkdir -p .typecheck/isolab
	for p in engine studies service; do ln -sfn ../../$$p .typecheck/isolab/$$p; done
	cd .typecheck && ../$(VENV)/bin/mypy --config-file ../pyproject.toml -p isolab.engine -p isolab.studies -p isolab.service

# The browser tests (tests/browser) drive Debian's Chromium through Playwright; install it where missing
# (root, or sudo when there is one). Playwright's own browser download is never used.
CHROMIUM ?= /usr/bin/chromium
SUDO := $(shell test "$$(id -u)" -eq 0 || command -v sudo)
browser:
	test -x $(CHROMIUM) || ($(SUDO) apt-get update && $(SUDO) apt-get install -y chromium)
