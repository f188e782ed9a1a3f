# stickslip: `make demo` runs the whole calibration story on the simulated MM3A,
# `make test` runs the test suite, `make docs` builds the documentation site into site/.
# All build .venv/ first if needed.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-fast test-explore test-calendar bench lint docs clean

# --no-compile: pip would compile every installed module one after the other (about 38 s of the
# install's 89 s here); Python compiles the ones a run imports on first use and keeps them.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile -e '.[plot,stats,audio,serial,anc300,dev,bluesky,docs,vision,opencv,serve,postgres]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/stickslip demo

# Python keeps compiled modules (__pycache__, git-ignored) during the tests even where the environment
# says PYTHONDONTWRITEBYTECODE: otherwise every `stickslip` a test starts compiles the package again
# (about 0.3 s of CPU each, hundreds of times) and pytest rewrites every test module again on every run.
PYTEST := env -u PYTHONDONTWRITEBYTECODE $(PY) -m pytest
COMPILE := env -u PYTHONDONTWRITEBYTECODE $(PY) -m compileall -q src tests/support

# The storage tests start a throwaway PostgreSQL server: .ci/postgres installs the server's binaries
# quietly when they are missing and apt-get can run (root, or sudo without a password); elsewhere
# those tests are skipped with the reason.
# mypy --strict runs beside the tests (its output kept and shown after theirs): the tests keep both
# cores busy but for their waits, and mypy alone would add about 25 s one after the other.
# One xdist worker more than the cores: about a fifth of a worker's time is waiting (real-time
# emulators, servers, the browser, subprocesses), which the extra worker fills; on two cores the
# suite took 419 s with three workers against 454-499 s with two, for the same CPU time.
WORKERS := $(PY) -c 'import os; n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(); print(min(5, (n or 1) + 1))'

test: $(STAMP)
	@bash .ci/postgres
	$(VENV)/bin/ruff check src tests benchmarks
	$(VENV)/bin/lint-imports
	@$(COMPILE)
	@echo "$(PY) -m mypy (beside the tests)"; $(PY) -m mypy > .mypy.log 2>&1 & types=$$!; \
	workers=$$($(WORKERS)); \
	echo "$(PYTEST) -q -n $$workers --dist loadgroup --durations=15"; \
	$(PYTEST) -q -n $$workers --dist loadgroup --durations=15; tests=$$?; \
	wait $$types; typed=$$?; echo "mypy:"; cat .mypy.log; rm -f .mypy.log; \
	test $$tests -eq 0 && test $$typed -eq 0

# Day-to-day: the suite without the tests marked slow (long batteries, documentation pages run as
# written, subprocesses); under 90 s on two cores. CI runs `make test`, which runs everything. The same
# workers as `make test` (one more than the cores: the waits of servers, emulators and the browser).
test-fast: $(STAMP)
	@bash .ci/postgres
	$(VENV)/bin/ruff check src tests benchmarks
	@$(COMPILE)
	workers=$$($(WORKERS)); $(PYTEST) -q -n $$workers --dist loadgroup -m "not slow" --durations=10

# The suite with fresh hypothesis draws (make test draws the same examples every run, so CI never
# fails on a lucky draw): run it now and then; pin a draw that breaks something as an @example.
test-explore: $(STAMP)
	STICKSLIP_HYPOTHESIS=explore $(PYTEST) -q -n auto --maxprocesses 4 -p no:cacheprovider

# The whole suite with the machine's clock faked (libfaketime, from the dev extra; it reaches
# subprocesses): 400 days ahead, then 30 s after midnight on New Year's Day at UTC+14.
FAKE = env LD_LIBRARY_PATH="$$($(PY) -c 'import libfaketime as f; print(f.get_reload_information()[1]["LD_LIBRARY_PATH"])')" \
	LD_PRELOAD=libfaketime.so.1 DONT_FAKE_MONOTONIC=1 FAKETIME_NO_CACHE=1

test-calendar: $(STAMP)
	$(FAKE) FAKETIME=+400d $(PY) -m pytest -q -p no:cacheprovider
	$(FAKE) FAKETIME='@2027-01-01 00:00:30' TZ=Pacific/Kiritimati $(PY) -m pytest -q -p no:cacheprovider

BENCH_STAMP := $(VENV)/.installed-bench

$(BENCH_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -e '.[bench]'
	touch $(BENCH_STAMP)

bench: $(BENCH_STAMP)
	@bash .ci/postgres
	$(PY) benchmarks/run.py

# mkdocs-material + mkdocstrings (the docs extra, pure Python, installed with the rest so the test suite
# builds the site too); --strict: a warning fails the build.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks
	$(VENV)/bin/lint-imports
	$(PY) -m mypy

clean:
	rm -rf $(VENV) build site *.egg-info src/*.egg-info .pytest_cache
