# The two commands of the README: `make run` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
DEFAULT_SCENARIO ?= scenarios/ball_rolling.yaml
# pytest workers (pytest-xdist): one per core of the 2-core CI machine; a test file stays on one worker
TEST_WORKERS ?= 2

.PHONY: install run test test-slow bench clean

install: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip
	$(BIN)/pip install -e '.[test]'
	touch $@

run: install
	$(BIN)/adaptive-c3 run $(DEFAULT_SCENARIO) --out runs/default
	@echo "figures and summary: runs/default/"

test: install
	$(BIN)/pytest -q -n $(TEST_WORKERS) --dist loadfile --durations=15

test-slow: install
	$(BIN)/pytest -q -m slow

bench: install
	$(BIN)/adaptive-c3 bench all --json runs/bench.json

clean:
	rm -rf $(VENV) runs .pytest_cache
