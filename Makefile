# anisosample — the two commands a new user runs are `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
SCALE  ?= small
# 2 workers by default (the reference machine has 2 cores); override with `make test JOBS=1`.
# Three workers on the 2 cores were slower (fresh clones of 2026-12-06, one right after the
# other: pytest 724 s with JOBS=3, all passing, against 637 s with 2, one test failing).
JOBS   ?= 2
# pytest-xdist's worksteal: each worker starts on half the tests and an idle one takes from the
# other's queue, so the run does not end waiting on a long test. Measured (2026-12-06, default
# suite, -n 2): wall minus half the summed test durations 34 s with --dist load (653.7 s), 24 s
# with worksteal (642.3 s), the tests' own durations the same (1240 / 1237 s).
DIST   ?= worksteal

.PHONY: demo demo-record test test-all lint bench figures clean-venv help \
        w-directions-accuracy \
        w-fig5-baselines \
        docs w-fig3 w-fig4 w-fig6 w-fig5 \
        w-fig6-baselines w-fig11 \
        tables w-aligned-end-to-end \
        render-scenes \
        w-fig7 w-fig8 w-fig9 w-fig10 w-fig12 \
        h-shading-points \
        h-fig2 h-table4 h-table5 beyond-warped-aligned \
        beyond-differentiable-tuning beyond-prefix-sets beyond-sequences \
        beyond-pixel-prefix beyond-sequences-four

help:
	@echo "make demo      set up .venv and run the headline experiment at small scale"
	@echo "make test      set up .venv and run the fast test suite"
	@echo "make test-all  include the slow statistical tests"
	@echo "make bench     run the benchmark scripts (prints their figures)"
	@echo "make figures   regenerate every paper figure (SCALE=small|paper)"
	@echo "make lint      ruff"
	@echo "make docs      regenerate docs/api.md and the measured numbers in docs/reproduction.md"

# The virtual environment is rebuilt when pyproject.toml changes.
$(VENV)/.installed: pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $@

# The demo writes under build/ (ignored): it leaves the committed record results/demo/ and
# `git status` as they were. `make demo-record` (part of `make figures`) rewrites that record.
DEMO_OUT ?= build/demo
demo: $(VENV)/.installed
	$(PY) experiments/demo.py --scale $(SCALE) --out $(DEMO_OUT)

demo-record: $(VENV)/.installed
	$(PY) experiments/demo.py --scale $(SCALE)

test: $(VENV)/.installed
	$(PY) -m pytest -q -m "not slow" -n $(JOBS) --dist $(DIST) tests

test-all: $(VENV)/.installed
	$(PY) -m pytest -q -n $(JOBS) --dist $(DIST) tests

lint: $(VENV)/.installed
	$(PY) -m ruff check anisosample experiments tests

bench: $(VENV)/.installed
	@for b in experiments/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

w-fig5-baselines: $(VENV)/.installed
	$(PY) experiments/w_fig5_baselines.py --scale $(SCALE)

w-fig6-baselines: $(VENV)/.installed
	$(PY) experiments/w_fig6_baselines.py --scale $(SCALE)

w-fig11: $(VENV)/.installed
	$(PY) experiments/w_fig11.py --scale $(SCALE)

figures: demo-record w-directions-accuracy w-fig5-baselines \
         w-fig3 w-fig4 w-fig6 w-fig5 \
         w-fig6-baselines w-fig11 \
         w-aligned-end-to-end \
         render-scenes \
         w-fig7 w-fig8 w-fig9 w-fig10 w-fig12 \
         h-shading-points \
         h-fig2 h-table4 h-table5 beyond-warped-aligned \
         beyond-differentiable-tuning beyond-prefix-sets beyond-sequences \
         beyond-pixel-prefix beyond-sequences-four
	$(PY) docs/fill_numbers.py --write
	@echo "figures done; docs/reproduction.md now quotes these results (make docs also refreshes docs/api.md)"

# Figure targets for experiment scripts (one each; SCALE=small|paper).
h-shading-points: $(VENV)/.installed
	$(PY) experiments/h_shading_points.py --scale $(SCALE)

h-fig2: $(VENV)/.installed
	$(PY) experiments/h_fig2.py --scale $(SCALE)

h-table4: $(VENV)/.installed
	$(PY) experiments/h_table4.py --scale $(SCALE)

h-table5: $(VENV)/.installed
	$(PY) experiments/h_table5.py --scale $(SCALE)

beyond-warped-aligned: $(VENV)/.installed
	$(PY) experiments/beyond_warped_aligned.py --scale $(SCALE)

beyond-differentiable-tuning: $(VENV)/.installed
	$(PY) experiments/beyond_differentiable_tuning.py --scale $(SCALE)

# W Sec. 7: aligned sets with a fixed isotropic prefix, and progressive aligned sequences.
beyond-prefix-sets: $(VENV)/.installed
	$(PY) experiments/beyond_prefix_sets.py --scale $(SCALE)

beyond-sequences: $(VENV)/.installed
	$(PY) experiments/beyond_sequences.py --scale $(SCALE)

beyond-sequences-four: $(VENV)/.installed
	$(PY) experiments/beyond_sequences.py --scale $(SCALE) --direction-count 4

w-fig3: $(VENV)/.installed
	$(PY) experiments/w_fig3.py --scale $(SCALE)

w-fig4: $(VENV)/.installed
	$(PY) experiments/w_fig4.py --scale $(SCALE)

w-fig6: $(VENV)/.installed
	$(PY) experiments/w_fig6.py --scale $(SCALE)

w-fig5: $(VENV)/.installed
	$(PY) experiments/w_fig5.py --scale $(SCALE)

# The API reference from the docstrings, and the measured numbers quoted in the report.
docs: $(VENV)/.installed
	$(PY) docs/gen_api.py
	$(PY) docs/fill_numbers.py --write

w-directions-accuracy: $(VENV)/.installed
	$(PY) experiments/w_directions_accuracy.py --scale $(SCALE)

# The paper's shipped aligned-set table, n = 4096 (W Sec. 5.4; resumable: rerun after an
# interruption; a finished table is verified and left alone; a rebuild takes about 5 min on a
# quiet 2-core machine: 6.6 s per set, experiments/bench_tables.py --full). The shipped n = 256 table keeps the
# aligned-only weights (see anisosample/tables.py). Other sizes: `anisosample tables build --n N`
# into the user cache; 4-direction: `--direction-count 4`.
TABLE_N ?= 4096
TABLE_BATCH ?= 1
tables: $(VENV)/.installed
	nice -n 10 $(PY) -m anisosample.cli tables build --n $(TABLE_N) --direction-count 3 \
		--batch $(TABLE_BATCH) --out anisosample/data/tables/d3_n$(TABLE_N)

w-aligned-end-to-end: $(VENV)/.installed
	$(PY) experiments/w_aligned_end_to_end.py --scale $(SCALE)
	$(PY) experiments/w_aligned_end_to_end.py --scale $(SCALE) --case two-edges
	$(PY) experiments/w_aligned_end_to_end.py --scale $(SCALE) --case four-edges

clean-venv:
	rm -rf $(VENV)

render-scenes: $(VENV)/.installed
	$(PY) experiments/render_scenes.py --scale $(SCALE)

# W render figures (W Sec. 6.2-6.3) on the JAX ray caster; w-fig10 reuses w-fig9's curves.
w-fig7: $(VENV)/.installed
	$(PY) experiments/w_fig7.py --scale $(SCALE)

w-fig8: $(VENV)/.installed
	$(PY) experiments/w_fig8.py --scale $(SCALE)

w-fig9: $(VENV)/.installed
	$(PY) experiments/w_fig9.py --scale $(SCALE)

w-fig10: $(VENV)/.installed
	$(PY) experiments/w_fig10.py --scale $(SCALE)

# The per-pixel sampler's prefix size at 256-512 spp, on w-fig9's one-edge pixels.
beyond-pixel-prefix: $(VENV)/.installed
	$(PY) experiments/beyond_pixel_prefix.py --scale $(SCALE)

w-fig12: $(VENV)/.installed
	$(PY) experiments/w_fig12.py --scale $(SCALE)
