# rob6 — the two commands: `make run` and `make test` (see README.md).
# Everything installs into ./.venv from uv.lock; a fresh machine needs only
# Python 3.11, pip, gcc and make (and Docker for the e2e tests).

PYTHON ?= python3
UV_VERSION := 0.13.9
TOOLS := .tools
UV := $(TOOLS)/bin/uv
VENV := .venv
BIN := $(VENV)/bin
SHARED_TRUTH ?= ../shared

# `make test PYTEST_ARGS="-m 'not docker'"` skips the slow Docker end-to-end tests
PYTEST_ARGS ?=

.PHONY: help install run test test-fast bench lock clean

help:
	@echo "make run    start router, services and gateway (simulated KR16 on port 5005)"
	@echo "make test   run every test (set ROB6_SKIP_DOCKER=1 to skip the Docker e2e tests)"
	@echo "make bench  run the benchmarks and print the tables"

$(UV):
	$(PYTHON) -m venv $(TOOLS)
	$(TOOLS)/bin/pip install --quiet uv==$(UV_VERSION)

$(VENV)/.installed: $(UV) uv.lock pyproject.toml shared/pyproject.toml services/*/pyproject.toml
	$(UV) sync --frozen --all-packages --python $(PYTHON)
	@touch $@

install: $(VENV)/.installed

lock: $(UV)
	$(UV) lock

run: install
	$(BIN)/rob6 run

test: install
	ROB6_SHARED=$(SHARED_TRUTH) $(BIN)/pytest $(PYTEST_ARGS)

test-fast: install
	ROB6_SKIP_DOCKER=1 ROB6_SHARED=$(SHARED_TRUTH) $(BIN)/pytest -x -q $(PYTEST_ARGS)

bench: install
	ROB6_SHARED=$(SHARED_TRUTH) $(BIN)/python -m bench

clean:
	rm -rf $(VENV) $(TOOLS) .pytest_cache .hypothesis
