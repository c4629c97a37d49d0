# anisosample — the two commands a new user runs are `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
SCALE  ?= small
# 2 workers by default (the reference machine has 2 cores); override with `make test JOBS=1`.
JOBS   ?= 2

.PHONY: demo test test-all lint bench figures clean-venv help \
        w-fig5-baselines

help:
	@echo "make demo      set up .venv and run the headline experiment at small scale"
	@echo "make test      set up .venv and run the fast test suite"
	@echo "make test-all  include the slow statistical tests"
	@echo "make bench     run the benchmark scripts (prints their figures)"
	@echo "make figures   regenerate every paper figure (SCALE=small|paper)"
	@echo "make lint      ruff"

# The virtual environment is rebuilt when pyproject.toml changes.
$(VENV)/.installed: pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $@

demo: $(VENV)/.installed
	$(PY) experiments/demo.py --scale $(SCALE)

test: $(VENV)/.installed
	$(PY) -m pytest -q -m "not slow" -n $(JOBS) tests

test-all: $(VENV)/.installed
	$(PY) -m pytest -q -n $(JOBS) tests

lint: $(VENV)/.installed
	$(PY) -m ruff check anisosample experiments tests

bench: $(VENV)/.installed
	@for b in experiments/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

w-fig5-baselines: $(VENV)/.installed
	$(PY) experiments/w_fig5_baselines.py --scale $(SCALE)

figures: w-fig5-baselines

clean-venv:
	rm -rf $(VENV)
