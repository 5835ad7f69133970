# Two commands do all the set-up on a fresh Debian/Ubuntu machine: `make demo` and `make test`.
# Both are idempotent: they install what is missing (system GL libraries, the virtual environment with
# the locked versions of requirements.lock, the package) and then run. `make test` also runs ruff and builds
# the documentation (mkdocs.yml) strictly.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test sysdeps testdeps venv lint typecheck lock bench clean

demo: sysdeps $(STAMP)
	$(VENV)/bin/vln-pilot run "Go to the bathroom" --spawn living_room

test: sysdeps testdeps $(STAMP) lint typecheck
	$(PY) -m pytest -q
	$(VENV)/bin/mkdocs build --strict --quiet --site-dir $(VENV)/site   # a broken link or anchor fails

sysdeps:
	@bash scripts/install-system-deps.sh gl

testdeps:
	@bash scripts/install-system-deps.sh browser

venv: $(STAMP)

# The locked versions first, then the package itself without resolving again.
$(STAMP): pyproject.toml requirements.lock
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.lock
	$(PY) -m pip install --quiet --no-deps -e .
	@touch $(STAMP)

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests bench scripts

typecheck: $(STAMP)
	$(VENV)/bin/mypy

# Pin requirements.lock to the versions installed in $(VENV) (after a test run on new versions).
lock: $(STAMP)
	$(PY) -m pip install --quiet pip-tools
	$(PY) -m pip freeze --exclude-editable > $(VENV)/tested.txt
	$(VENV)/bin/pip-compile --quiet --extra test --constraint $(VENV)/tested.txt --strip-extras --allow-unsafe \
		--no-emit-index-url --no-emit-find-links --output-file requirements.lock pyproject.toml
	sed -i '/#   -c /d' requirements.lock

bench: sysdeps $(STAMP)
	$(PY) bench/step_cost.py

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info
