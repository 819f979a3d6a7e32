# Two set-up commands: `make demo` and `make test`. Both work on a fresh machine
# with Python 3.11 and make; they create .venv and install the project into it.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
BENCH_STAMP := $(VENV)/.installed-bench
# pytest-xdist runs one worker per core; BLAS threads on top would oversubscribe them
SINGLE_THREADED := OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1

.PHONY: demo test bench bench-large bench-coverage bench-mc-coverage clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

$(BENCH_STAMP): pyproject.toml $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,bench]'
	touch $(BENCH_STAMP)

demo: $(STAMP)
	$(BIN)/python examples/flux_table.py

test: $(STAMP)
	$(SINGLE_THREADED) $(BIN)/python -m pytest -q -n 2

bench: $(BENCH_STAMP)
	$(BIN)/python benchmarks/run.py

bench-large: $(BENCH_STAMP)
	$(BIN)/python benchmarks/large.py

bench-coverage: $(BENCH_STAMP)
	$(BIN)/python benchmarks/error_coverage.py

bench-mc-coverage: $(BENCH_STAMP)
	$(SINGLE_THREADED) $(BIN)/python benchmarks/mc_coverage.py

clean:
	rm -rf $(VENV) build *.egg-info
