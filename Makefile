# raysim: one place for set-up, the demo, the tests and the benchmarks.
# `make demo` on a fresh Debian machine with Python 3.11+ does all the set-up.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

# Warp compiles kernels once into this ignored folder; later runs load them.
export WARP_CACHE_PATH := $(CURDIR)/.cache/warp
export MPLBACKEND := Agg
export PYTHONUNBUFFERED := 1

.PHONY: all install demo test lint bench clean

all: test

$(STAMP): pyproject.toml scripts/install-system-deps.sh
	bash scripts/install-system-deps.sh
	$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "raysim needs Python 3.11+"'
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	@mkdir -p out
	$(BIN)/raysim simulate scenes/paper_go.toml -o out/paper_go.nc
	$(BIN)/raysim render out/paper_go.nc -o out/paper_go_fa.png
	$(BIN)/raysim report out/paper_go.nc -o out/report
	@echo "demo outputs are in $(CURDIR)/out/; the paper's figures: $(CURDIR)/out/report/report.html"

test: $(STAMP)
	$(BIN)/python -m pytest

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports

bench: $(STAMP)
	$(BIN)/python benchmarks/run.py

clean:
	rm -rf out .cache .pytest_cache
