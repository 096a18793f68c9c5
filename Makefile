# Two entry points that work on a fresh machine with Python 3.11+:
#   make demo   set everything up, then reproduce the paper's Tables 1 and 2
#   make test   set everything up, then run the test suite
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: setup demo test bench clean

# ends by compiling every command's kernels once (persuasive compile), so that demo and test
# start warm
$(BIN)/persuasive: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	$(BIN)/persuasive compile
	touch $@

setup: $(BIN)/persuasive

demo: setup
	$(BIN)/persuasive reproduce all

test: setup
	$(BIN)/python -m pytest -n 2 --dist loadfile

bench: setup
	$(BIN)/persuasive bench --full --reference

clean:
	rm -rf $(VENV) results .pytest_cache .hypothesis
	find src -name __pycache__ -prune -exec rm -rf {} +
