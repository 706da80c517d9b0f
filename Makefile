# rob6 — the two commands: `make run` and `make test` (see README.md).
# Everything installs into ./.venv from uv.lock; a fresh machine needs only
# Python 3.11-3.13, pip, gcc, cargo and make (and Docker for the e2e tests).

PYTHON ?= python3
UV_VERSION := 0.13.9
TOOLS := .tools
UV := $(TOOLS)/bin/uv
VENV := .venv
BIN := $(VENV)/bin
SHARED_TRUTH ?= ../shared

# `make test PYTEST_ARGS="-m 'not docker'"` skips the slow Docker end-to-end tests
PYTEST_ARGS ?=

.PHONY: help install run test test-fast check bench images lock clean transcripts python-version rust

help:
	@echo "make run    start router, services and gateway (simulated KR16 on port 5005)"
	@echo "make test   run every test (set ROB6_SKIP_DOCKER=1 to skip the Docker e2e tests)"
	@echo "make check  lint (ruff) and type-check (mypy), configured in pyproject.toml"
	@echo "make bench  run the benchmarks and print the tables"
	@echo "make images build every container image offline (deploy/build-images.sh)"

# rob6 runs on CPython 3.11-3.13 (uv.lock resolves for all three; every dependency has wheels)
python-version:
	@$(PYTHON) -c 'import sys; ok = (3, 11) <= sys.version_info[:2] <= (3, 13); \
		ok or print(f"rob6 needs Python 3.11, 3.12 or 3.13; $(PYTHON) is {sys.version.split()[0]}: " \
		"choose one with make PYTHON=python3.12 ...", file=sys.stderr); sys.exit(not ok)' \
		|| { command -v $(PYTHON) >/dev/null || echo "rob6: no $(PYTHON) here; choose one with make PYTHON=..." >&2; exit 1; }

# the recorder's writer (services/recorder/native) is Rust, built by uv sync through maturin
rust:
	@command -v cargo >/dev/null || { echo "rob6: no cargo here: the recorder's writer is Rust" \
		"(services/recorder/native); install a Rust toolchain, e.g. with rustup" >&2; exit 1; }

$(UV): | python-version
	$(PYTHON) -m venv $(TOOLS)
	$(TOOLS)/bin/pip install --quiet uv==$(UV_VERSION)

$(VENV)/.installed: $(UV) | python-version rust
$(VENV)/.installed: uv.lock pyproject.toml $(wildcard shared/pyproject.toml services/*/pyproject.toml controllers/*/pyproject.toml clients/*/pyproject.toml)
$(VENV)/.installed: $(wildcard services/recorder/native/Cargo.* services/recorder/native/src/*.rs)
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

# ruff: pyflakes, import order, bugbear, E4/E7/E9, pyupgrade, simplify, return, pylint's
# errors, warnings, conventions and idiom refactors, unused noqa; mypy: strict for every
# package, the harness, bench and tests (pyproject.toml)
check: install
	$(BIN)/ruff check .
	$(BIN)/mypy

bench: install
	$(BIN)/python -m bench

# every rob6 image, offline (the tests build them themselves, once per run, before the first test)
images: install
	UV=$(UV) bash deploy/build-images.sh

# the original's transcripts travel with the tests: refresh the copy from the ground truth
transcripts:
	find tests/transcripts -mindepth 1 ! -name ORIGIN.md -delete
	cp -r $(SHARED_TRUTH)/conformance/. tests/transcripts/

clean:
	rm -rf $(VENV) $(TOOLS) .pytest_cache .hypothesis
