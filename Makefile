# Two set-up commands: `make demo` and `make test`. Both work on a fresh machine
# with Python 3.11 and make; they create .venv and install the project into it.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
KERNELS_STAMP := $(VENV)/.kernels
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

# The kernels compiled once here, not on a user's first run: numba's cache for
# the common routes and the ahead-of-time copies a small solve runs on
# (python -m markov.warmup; again when a source of markov changes).
$(KERNELS_STAMP): $(STAMP) $(wildcard markov/*.py markov/*/*.py markov/*/*/*.py)
	$(BIN)/python -m markov.warmup
	touch $(KERNELS_STAMP)

$(BENCH_STAMP): pyproject.toml $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,bench]'
	touch $(BENCH_STAMP)

demo: $(KERNELS_STAMP)
	$(BIN)/python examples/flux_table.py

test: $(KERNELS_STAMP)
	$(SINGLE_THREADED) $(BIN)/python -m pytest -q -n 2

bench: $(BENCH_STAMP) $(KERNELS_STAMP)
	$(BIN)/python benchmarks/run.py
	$(BIN)/python benchmarks/startup.py

bench-large: $(BENCH_STAMP)
	$(BIN)/python benchmarks/large.py
	$(BIN)/python benchmarks/roads_large.py
	$(BIN)/python benchmarks/mps_roads.py
	$(BIN)/python benchmarks/pair_levels.py
	$(BIN)/python benchmarks/bandwidth.py
	$(BIN)/python benchmarks/blas_threads.py
	$(BIN)/python benchmarks/solver_vectors.py --large
	$(BIN)/python benchmarks/spectrum_sectors.py --large

bench-coverage: $(BENCH_STAMP)
	$(BIN)/python benchmarks/error_coverage.py

bench-mc-coverage: $(BENCH_STAMP)
	$(SINGLE_THREADED) $(BIN)/python benchmarks/mc_coverage.py

clean:
	rm -rf $(VENV) build *.egg-info
