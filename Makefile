# swarmpose: `make demo` runs the main job, `make test` the fast tests (about 2 minutes),
# `make test-all` every test (CI).
# The first call installs what is missing: system libraries (apt-get, as root), the
# virtual environment .venv and the package with its dependencies from PyPI.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-all lint setup clean

demo: $(STAMP)
	$(BIN)/swarmpose demo

test: $(STAMP)
	$(BIN)/ruff check service tests examples
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -q -n 2 -m "not slow"

test-all: $(STAMP)
	$(BIN)/ruff check service tests examples
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --durations=15

lint: $(STAMP)
	$(BIN)/ruff check service tests examples
	$(BIN)/lint-imports

setup: $(STAMP)

$(STAMP): pyproject.toml scripts/install-system-deps.sh
	PYTHON=$(PYTHON) bash scripts/install-system-deps.sh
	test -x $(BIN)/pip || $(PYTHON) -m venv --clear $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

clean:
	rm -rf $(VENV) demo-output build *.egg-info .pytest_cache .ruff_cache
