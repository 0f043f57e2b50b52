# raysim: one place for set-up, the demo, the tests and the benchmarks.
# `make demo` on a fresh Debian machine with Python 3.11+ does all the set-up.
#
# Dependencies: by default the versions pinned in constraints.txt (a lock from a fresh
# resolve; `make lock` refreshes it). RAYSIM_DEPS=newest takes the newest releases the
# bounds in pyproject.toml allow, RAYSIM_DEPS=lowest exactly those lower bounds; each mode
# has its own virtual environment.

PYTHON      ?= python3
RAYSIM_DEPS ?= lock

ifeq ($(RAYSIM_DEPS),lock)
VENV        := .venv
CONSTRAINTS := constraints.txt
else ifeq ($(RAYSIM_DEPS),newest)
VENV        := .venv-newest
CONSTRAINTS :=
else ifeq ($(RAYSIM_DEPS),lowest)
VENV        := .venv-lowest
CONSTRAINTS := .cache/constraints-lowest.txt
else
$(error RAYSIM_DEPS must be lock, newest or lowest, not '$(RAYSIM_DEPS)')
endif

BIN   := $(VENV)/bin
STAMP := $(VENV)/.installed

# Warp compiles kernels once into this ignored folder (one per dependency mode: the Warp
# versions differ); later runs load them.
export WARP_CACHE_PATH := $(CURDIR)/.cache/warp$(if $(filter lock,$(RAYSIM_DEPS)),,-$(RAYSIM_DEPS))
export MPLBACKEND := Agg
export PYTHONUNBUFFERED := 1

.PHONY: all install demo test docs lint bench lock clean

all: test

.cache/constraints-lowest.txt: pyproject.toml scripts/constraints.py
	@mkdir -p .cache
	$(PYTHON) scripts/constraints.py lowest $@

$(STAMP): pyproject.toml scripts/install-system-deps.sh $(CONSTRAINTS)
	bash scripts/install-system-deps.sh
	$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "raysim needs Python 3.11+"'
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet $(if $(CONSTRAINTS),-c $(CONSTRAINTS),--upgrade --upgrade-strategy eager) -e '.[test,docs]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	@mkdir -p out
	$(BIN)/raysim simulate paper_go -o out/paper_go.nc
	$(BIN)/raysim render out/paper_go.nc -o out/paper_go_fa.png
	$(BIN)/raysim report out/paper_go.nc -o out/report
	@echo "demo outputs are in $(CURDIR)/out/; the paper's figures: $(CURDIR)/out/report/report.html"

# The suite on TEST_JOBS processes (pytest-xdist), 2 by default as the CI machine has two
# cores: a third less wall time, as much of it waits on subprocesses, Dask and sockets. A
# file's tests stay on one process, so a module's fixtures are made once. TEST_JOBS=0 runs
# the suite in this process. Each worker gets one BLAS thread: OpenBLAS starts one per core,
# spinning while it waits for work, and with two workers on two cores they fought each other
# (test_budget.py and test_gain.py: 165 CPU-seconds against 88 with one thread a worker).
TEST_JOBS ?= 2
TEST_ENV = $(if $(filter 0,$(TEST_JOBS)),,OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1)

test: $(STAMP)
	$(TEST_ENV) $(BIN)/python -m pytest -n $(TEST_JOBS) --dist loadfile

# The documentation site: Markdown pages, the API reference from the docstrings and the
# tutorials in examples/ run on small grids; warnings are errors. Output: docs/_build/html.
docs: $(STAMP)
	rm -rf docs/_build docs/tutorials docs/reference/generated
	$(BIN)/python -m sphinx -b html -W --keep-going docs docs/_build/html
	@echo "the site: $(CURDIR)/docs/_build/html/index.html"

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports

bench: $(STAMP)
	$(BIN)/python benchmarks/run.py

# Refresh constraints.txt: resolve the newest versions pyproject.toml allows in a scratch
# environment and pin every package it installed (commit the result).
lock:
	rm -rf .cache/lock-venv
	$(PYTHON) -m venv .cache/lock-venv
	.cache/lock-venv/bin/python -m pip install --quiet --upgrade pip
	.cache/lock-venv/bin/python -m pip install --quiet '.[test,docs]'
	{ echo "# pinned by 'make lock' from a fresh resolve of pyproject.toml; make test and make demo use it"; \
	  .cache/lock-venv/bin/python -m pip freeze --exclude raysim; } > constraints.txt
	rm -rf .cache/lock-venv
	@echo "constraints.txt refreshed; run make test, then commit it"

clean:
	rm -rf out .cache .pytest_cache docs/_build docs/tutorials docs/reference/generated
