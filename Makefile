# windrig: set-up and entry points.
#
# `make test` and `make demo` each do the whole set-up on a fresh machine that has only Python 3.11,
# make and git: a virtualenv in .venv, the package installed editable with its test, gui (the Qt
# binding and pyqtgraph) and dask (dask.distributed for `windrig reprocess`) extras, and the
# Debian libraries the Qt binding needs to start offscreen. Re-runs skip what is already done.
#
#   make test            run the test suite (pytest; extra arguments in PYTEST_ARGS="...")
#   make test-fast       run its pure part alone (no socket, thread, process or real clock)
#   make demo            run a whole simulated campaign, results in demo_output/
#   make docs            build the documentation site into docs/_build/html (warnings are errors)
#   make bench           run every benchmark in its quick mode (CI), results in benchmarks/results/quick
#   make bench BENCH_MODE=full   run them in full (hours), results in docs/validation/results
#   make lint            ruff check (ruff is installed into .venv for this target only)
#   make typecheck       mypy (likewise installed for this target only)
#   make clean           remove .venv, demo_output and caches
#
# PYTHON=/path/to/python3.11 picks the interpreter that builds the venv.

SHELL := /bin/bash
.DEFAULT_GOAL := test
.DELETE_ON_ERROR:

VENV := .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip
STAMP := $(VENV)/.installed
# The example driver plugin (examples/windrig-dsa3217), installed as a distribution of its own.
PLUGIN := examples/windrig-dsa3217
PLUGIN_STAMP := $(VENV)/.plugin-installed
RUFF_VERSION := 0.17.5
MYPY_VERSION := 2.4.1

# python3.11 first, else python3; the version is checked when the venv is made.
PYTHON ?= $(shell command -v python3.11 || command -v python3)

# Tests and the demo never open a window, and never need a display.
test test-fast demo screenshot: export QT_QPA_PLATFORM := offscreen
test test-fast demo screenshot: export MPLBACKEND := Agg

.PHONY: test test-fast demo docs bench report-example screenshot lint typecheck setup qt-libs clean

# The suite is split by the `realtime` marker (pyproject.toml), not by folder. The pure part
# (computations, parsers, files, scripted byte exchanges, the doctests of daq, ident and
# simulators) runs on two workers. The real-time part (sockets, the simulated rig, threads with
# deadlines, real clocks, Qt event loops with timers, and Dask clusters, which each want the
# dashboard's port) runs as one process. `make test` runs the two side by side with the pure
# part at the lowest CPU priority (nice 19): the real-time tests spend most of their time
# waiting for the simulated rig's real time, and the pure part fills those idle cycles without
# taking a core from a deadline (the scheduler gives a nice-0 task that wakes the CPU at once).
# Each part has its own temporary directory; the pure part's report is printed when both are
# done. tests/test_suite_split.py fails on a real-time test module left unmarked. (Exit code
# 5, nothing collected, is a PYTEST_ARGS filter's doing.) The pure part's workers steal each
# other's queued tests (--dist worksteal): a few long tests left at the end of one queue would
# otherwise keep a core idle.
PURE_TESTS := $(PY) -m pytest -q -p no:cacheprovider --durations=40 -n 2 --dist worksteal \
    -m "not realtime"
REALTIME_TESTS := $(PY) -m pytest -q -p no:cacheprovider --durations=40 -m realtime

# Both parts always run; the target fails if either did.
test: setup
	@status=0; scratch=$$(mktemp -d); \
	( nice -n 19 $(PURE_TESTS) --basetemp=$$scratch/pure $(PYTEST_ARGS) \
	    > $$scratch/pure.log 2>&1; echo $$? > $$scratch/pure.rc ) & \
	$(REALTIME_TESTS) --basetemp=$$scratch/realtime $(PYTEST_ARGS) || [ $$? -eq 5 ] || status=1; \
	wait; echo "--- the pure part (run beside the real-time part, at nice 19) ---"; \
	cat $$scratch/pure.log; pure=$$(cat $$scratch/pure.rc); \
	[ $$pure -eq 0 ] || [ $$pure -eq 5 ] || status=1; \
	rm -rf $$scratch; exit $$status

# The pure part alone, for the edit-test loop of numerical work (no socket, rig or real clock).
test-fast: setup
	@$(PURE_TESTS) $(PYTEST_ARGS) || [ $$? -eq 5 ]

demo: setup
	$(VENV)/bin/windrig demo --out demo_output

# The example design report in docs (docs/examples/bridge_report): the example bridge, its
# deck's table, buffeting at 30 and 45 m/s.
report-example: setup
	rm -rf docs/examples/bridge_report
	$(VENV)/bin/windrig bridge daq/rig_configs/bridges/example_bridge.json \
	    --aero daq/rig_configs/bridges/example_deck_table.csv --buffeting 30,45 \
	    --wind daq/rig_configs/bridges/example_wind.toml --out docs/examples/bridge_report

# The README's picture of the live console (a simulated session, three automatic releases).
screenshot: setup
	$(VENV)/bin/windrig gui --config rig_configs/sim_flat_plate.toml --simulate \
	    --auto-release 550,700,850 --screenshot docs/console_screenshot.png --after 31 \
	    --size 1600 1000

setup: $(STAMP) $(PLUGIN_STAMP) qt-libs

# The site: Sphinx over docs/ (docs/conf.py says why Sphinx), every warning an error, all of them
# listed (--keep-going). The API reference's pages are written by docs/_apiref.py on each build.
DOCS_STAMP := $(VENV)/.docs-installed
docs: setup $(DOCS_STAMP)
	$(VENV)/bin/sphinx-build -W --keep-going -q -j auto -b html docs docs/_build/html
	@echo "the site: docs/_build/html/index.html"

# The benchmarks (benchmarks/run.py): the quick mode shows each one runs and writes its result
# files (two at a time: its figures do not count); the full mode, one at a time, writes the files
# the validation pages include (BENCH_ARGS="--only NAME").
BENCH_MODE ?= quick
bench: setup
	$(PY) benchmarks/run.py --mode $(BENCH_MODE) $(if $(filter quick,$(BENCH_MODE)),--jobs 2) $(BENCH_ARGS)

$(DOCS_STAMP): pyproject.toml $(STAMP)
	$(PIP) install -q --progress-bar off -e '.[docs]'
	@touch $@

# Quiet when nothing is missing; installs the Debian packages (apt-get) when something is.
qt-libs: $(STAMP)
	@bash .ci/ensure_qt_libs.sh $(PY)

$(PY):
	@py="$(PYTHON)"; \
	if [ -z "$$py" ]; then \
	  echo "error: no python3.11 or python3 on PATH; windrig needs Python >= 3.11" >&2; exit 1; \
	fi; \
	if ! "$$py" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then \
	  echo "error: windrig needs Python >= 3.11, but $$py is $$("$$py" -V 2>&1)." >&2; \
	  echo "       Install python3.11, or run: make PYTHON=/path/to/python3.11 ..." >&2; exit 1; \
	fi; \
	echo "creating $(VENV) with $$py ($$("$$py" -V 2>&1))"; \
	if ! "$$py" -m venv $(VENV); then \
	  rm -rf $(VENV); \
	  echo "error: '$$py -m venv' failed (on Debian: apt-get install python3-venv)" >&2; exit 1; \
	fi

# Re-install when the metadata changes, or when a top-level package first appears (the editable
# install maps the packages that exist at install time).
$(STAMP): pyproject.toml Makefile $(wildcard daq/__init__.py ident/__init__.py simulators/__init__.py) | $(PY)
	$(PIP) install -q --progress-bar off -e '.[test,dask,gui]'
	@touch $@

# The example driver plugin, a distribution of its own (examples/windrig-dsa3217): installed
# beside windrig so that its entry points are found and `make test` runs its tests too.
$(PLUGIN_STAMP): $(PLUGIN)/pyproject.toml $(STAMP)
	$(PIP) install -q --progress-bar off --no-deps -e $(PLUGIN)
	@touch $@

lint: $(VENV)/.ruff-$(RUFF_VERSION)
	$(VENV)/bin/ruff check .

$(VENV)/.ruff-$(RUFF_VERSION): | $(PY)
	$(PIP) install -q --progress-bar off 'ruff==$(RUFF_VERSION)'
	@touch $@

typecheck: $(STAMP) $(VENV)/.mypy-$(MYPY_VERSION)
	$(VENV)/bin/mypy

$(VENV)/.mypy-$(MYPY_VERSION): | $(PY)
	$(PIP) install -q --progress-bar off 'mypy==$(MYPY_VERSION)'
	@touch $@

clean:
	rm -rf $(VENV) demo_output build docs/_build docs/reference/api .pytest_cache .hypothesis .mypy_cache .ruff_cache *.egg-info
	find . -path ./.git -prune -o -type d -name __pycache__ -prune -exec rm -rf {} +
