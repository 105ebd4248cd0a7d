# augnet: `make run` starts the main job, `make test` runs every test (what CI runs), `make test-fast`
# the inner loop: every test not marked `slow` or `postgres` (under 3 minutes; tiers in tests/README.md).
# All create .venv when missing and install what the project needs, Debian packages included.

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SUDO   := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# Debian packages the tests drive: RTKLIB (convbin, rnx2rtkp, str2str, rtkrcv), curl, and headless
# Chromium with its WebDriver for the console's browser test.
DEBS   := rtklib curl chromium chromium-driver
DEB_CHECK := command -v rnx2rtkp >/dev/null && command -v convbin >/dev/null && command -v str2str >/dev/null && command -v rtkrcv >/dev/null && command -v curl >/dev/null && command -v chromium >/dev/null && command -v chromedriver >/dev/null

# One pytest worker per core, a whole test file to a worker (module fixtures are built once), files handed out in
# tests/conftest.py's order (longest first; xdist would reorder them by test count); WORKERS=0: serial.
WORKERS  ?= 2
PARALLEL := $(if $(filter 0,$(WORKERS)),,-n $(WORKERS) --dist loadfile --no-loadscope-reorder)

.PHONY: run test test-fast bench debs venv clean

run: venv
	$(VENV)/bin/augnet up demo

test: venv debs
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(PY) -m pytest -q $(PARALLEL)

test-fast: venv debs
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(PY) -m pytest -q $(PARALLEL) -m "not slow and not postgres"

bench: venv debs
	$(VENV)/bin/augnet bench all

venv: $(STAMP)

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV) || { $(SUDO) apt-get update -q && $(SUDO) apt-get install -y -q python3-venv && $(PYTHON) -m venv $(VENV); }
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	@touch $(STAMP)

debs:
	@$(DEB_CHECK) || { $(SUDO) apt-get update -q && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -q $(DEBS); }

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis
