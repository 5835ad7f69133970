# Two commands do all the set-up on a fresh Debian/Ubuntu machine: `make demo` and `make test`.
# Both are idempotent: they install what is missing (system GL libraries, the virtual environment,
# the package) and then run. `make test` also builds the documentation (mkdocs.yml) strictly.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test sysdeps testdeps venv lint bench clean

demo: sysdeps $(STAMP)
	$(VENV)/bin/vln-pilot run "Go to the bathroom" --spawn living_room

test: sysdeps testdeps $(STAMP)
	$(PY) -m pytest -q
	$(VENV)/bin/mkdocs build --strict --quiet --site-dir $(VENV)/site   # a broken link or anchor fails

sysdeps:
	@bash scripts/install-system-deps.sh gl

testdeps:
	@bash scripts/install-system-deps.sh browser

venv: $(STAMP)

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests bench

bench: sysdeps $(STAMP)
	$(PY) bench/step_cost.py

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info
