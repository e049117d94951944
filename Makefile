# The two commands of the README: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test bench lint setup clean

TESTS  := $(VENV)/.installed-tests
# setuptools tells every editable install to beware of folders named like the package: none is here
QUIET_PIP := PYTHONWARNINGS=ignore::UserWarning $(BIN)/python

setup: $(TESTS)

# what users need: sonibus itself
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(QUIET_PIP) -m pip install --quiet -e .
	touch $(STAMP)

# what the tests need besides: the test extra and the test plug-in
$(TESTS): $(STAMP) tests/plugin/pyproject.toml
	$(QUIET_PIP) -m pip install --quiet -e '.[test]' -e tests/plugin
	touch $(TESTS)

# Ctrl-C is how a demo ends: no "Error 130" from make (the trap keeps the shell
# alive to see sonibus's exit status; sonibus itself still gets the Ctrl-C)
demo: $(STAMP)
	trap true INT; $(BIN)/sonibus demo $(DEMO_ARGS) || test $$? -eq 130

# the suite waits on processes and networks more than it computes (2 workers kept 2 cores ~35 % busy):
# three workers on two cores; the few tests that need the machine to keep up (steady audio) are marked
# realtime and run alone (tests/turns.py); a worker that crashes ends the run (xdist's replacement
# worker once left the run waiting for ever); the 15 slowest tests are listed, so a suite creeping
# toward CI's 15 minutes shows where
TEST_WORKERS ?= 3
test: $(TESTS)
	bash scripts/test-tools.sh
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadscope --max-worker-restart 0 --durations 15

bench: $(TESTS)
	bash scripts/test-tools.sh
	$(BIN)/python bench/run.py

lint: $(TESTS)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
