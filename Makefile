# Two entry points: `make demo` and `make test` (`make test-fast` skips the tests marked
# slow: notebooks, training runs, full-length evaluations). All create .venv if missing and
# install the package with pinned dependencies (torch==2.13.0: CPU wheel, keeps CI fast).
# `make test` also builds the documentation site strictly (`make docs-build`) and checks the
# distribution (`make dist-check`: wheel and sdist built, checked, installed and run);
# `make docs` serves the site locally.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SITE_DIR := build/site
export MUJOCO_GL ?= egl
# Material for MkDocs prints a banner about MkDocs 2 on every build
export NO_MKDOCS_2_WARNING := 1

.PHONY: demo test test-fast install lint format clean bench docs docs-build dist-check

$(STAMP): pyproject.toml Makefile
	@# headless rendering (notebooks, videos) uses Mesa's EGL; install it where it is missing
	@ldconfig -p | grep -q libEGL_mesa || { apt-get update -qq && \
		apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri; } || \
		echo "warning: Mesa EGL not installed: offscreen rendering will not work"
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e ".[dev]" "torch==2.13.0"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/myoexo demo

test: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy
	$(VENV)/bin/mkdocs build --strict --site-dir $(SITE_DIR)
	PY=$(CURDIR)/$(PY) bash .ci/check_dist.sh
	$(PY) -m pytest -q tests

docs: $(STAMP)
	$(VENV)/bin/mkdocs serve

docs-build: $(STAMP)
	$(VENV)/bin/mkdocs build --strict --site-dir $(SITE_DIR)

dist-check: $(STAMP)
	PY=$(CURDIR)/$(PY) bash .ci/check_dist.sh

test-fast: $(STAMP)
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -q -m "not slow" tests

lint: $(STAMP)
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check . && $(VENV)/bin/mypy

format: $(STAMP)
	$(VENV)/bin/ruff format . && $(VENV)/bin/ruff check --fix .

bench: $(STAMP)
	$(PY) benchmarks/bench_physics.py
	$(PY) benchmarks/bench_env.py
	$(PY) benchmarks/bench_evaluation.py

clean:
	rm -rf $(VENV) build dist *.egg-info
