# Two entry points: `make demo` and `make test` (`make test-fast` skips the tests marked
# slow: notebooks, training runs, full-length evaluations). Both create .venv if missing and
# install the package with pinned dependencies (torch==2.13.0 first: the CPU wheel, keeps CI
# fast). `make demo` installs the package alone (RUN_STAMP); `make test` and the other
# developer targets add the `dev` extra on top (DEV_STAMP: tests, linters, the docs site, the
# build tools, the optional back-ends), in either order.
# `make test` also builds the documentation site strictly (`make docs-build`), checks that
# the committed results tables are what their result sets give (tools/render_tables.py
# --check) and checks the distribution (`make dist-check`: wheel and sdist built, checked,
# installed and run); `make docs` serves the site locally.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
RUN_STAMP := $(VENV)/.installed-run
DEV_STAMP := $(VENV)/.installed-dev
SITE_DIR := build/site
# the tests run on 2 pytest-xdist workers, each test file on one of them (its module fixtures
# built once); `make test PYTEST_WORKERS=` runs them in one process
PYTEST_WORKERS ?= -n 2 --dist loadfile
export MUJOCO_GL ?= egl
# Material for MkDocs prints a banner about MkDocs 2 on every build
export NO_MKDOCS_2_WARNING := 1

.PHONY: demo test test-fast install lint format clean bench docs docs-build dist-check

# the package and what it needs to run (`make demo`); the developer tools (`make test` and
# the targets below it) come with the `dev` extra, in one pass when nothing is installed yet
define install_package
	@# headless rendering (notebooks, videos) uses Mesa's EGL; install it where it is missing
	@ldconfig -p | grep -q libEGL_mesa || { apt-get update -qq && \
		apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri; } || \
		echo "warning: Mesa EGL not installed: offscreen rendering will not work"
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e "$(1)" "torch==2.13.0"
endef

$(RUN_STAMP): pyproject.toml Makefile
	$(call install_package,.)
	touch $(RUN_STAMP)

$(DEV_STAMP): pyproject.toml Makefile
	$(call install_package,.[dev])
	touch $(DEV_STAMP) $(RUN_STAMP)

install: $(DEV_STAMP)

demo: $(RUN_STAMP)
	$(VENV)/bin/myoexo demo

test: $(DEV_STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports
	$(VENV)/bin/mkdocs build --strict --site-dir $(SITE_DIR)
	$(PY) tools/render_tables.py --check
	PY=$(CURDIR)/$(PY) bash .ci/check_dist.sh
	$(PY) -m pytest -q --durations=15 $(PYTEST_WORKERS) tests

docs: $(DEV_STAMP)
	$(VENV)/bin/mkdocs serve

docs-build: $(DEV_STAMP)
	$(VENV)/bin/mkdocs build --strict --site-dir $(SITE_DIR)

dist-check: $(DEV_STAMP)
	PY=$(CURDIR)/$(PY) bash .ci/check_dist.sh

test-fast: $(DEV_STAMP)
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -q $(PYTEST_WORKERS) -m "not slow" tests

lint: $(DEV_STAMP)
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check . && $(VENV)/bin/mypy

format: $(DEV_STAMP)
	$(VENV)/bin/ruff format . && $(VENV)/bin/ruff check --fix .

bench: $(DEV_STAMP)
	$(PY) benchmarks/bench_physics.py
	$(PY) benchmarks/bench_env.py
	$(PY) benchmarks/bench_evaluation.py

clean:
	rm -rf $(VENV) build dist *.egg-info
