# piste: two commands.  `make demo` sets up and runs the main job; `make test` sets up and runs the tests.
# Both install exactly the versions CI tested (constraints.txt); `make test-latest` tries the newest.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
APT_PKGS := libegl1 libgl1 libgl1-mesa-dri
EXTRAS ?= gl,video,gltf,dask,docs,dev

.PHONY: demo test test-latest setup system test-tools venv bench docs clean lock blender-addon

demo: setup
	$(BIN)/piste demo

test: setup test-tools
	$(BIN)/python -m pytest -q

# Every benchmark (peers from the bench extra, side by side), then one table: goal / piste / peer / ratio,
# written to benchmarks/RESULTS.md (the README quotes it).  Headless machines: the window benchmark runs
# under xvfb-run when Xvfb is installed, else it reports itself skipped (exit 0 either way).
# BENCH_ARGS=--full for the long runs (default: each benchmark's --quick).
bench: setup
	$(BIN)/pip install -q -c constraints.txt -e '.[bench]'
	$(BIN)/python benchmarks/summary.py $(BENCH_ARGS)

setup: system $(VENV)/.installed

# Headless OpenGL (Mesa llvmpipe through EGL) comes from Debian packages.
system:
	@missing=""; for p in $(APT_PKGS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  echo "installing system packages:$$missing"; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing; \
	fi
	@$(PY) -c 'import sys, ensurepip; assert sys.version_info >= (3, 11)' 2>/dev/null || { \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  echo "installing python3 (3.11+) with venv"; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq python3 python3-venv python3-pip; }

# Real clients the tests drive (glTF validator, Blender, Chromium, Xvfb).
test-tools:
	bash tools/setup-test-tools.sh

$(VENV)/.installed: pyproject.toml constraints.txt
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -c constraints.txt -e '.[$(EXTRAS)]'
	touch $@

# The newest releases of every dependency, in a venv of their own (not the tested set).
test-latest: system test-tools
	$(PY) -m venv .venv-latest
	.venv-latest/bin/pip install -q --upgrade pip
	.venv-latest/bin/pip install -q --upgrade -e '.[$(EXTRAS)]'
	.venv-latest/bin/python -m pytest -q

# Re-record constraints.txt from the current venv (after a deliberate upgrade).
lock:
	$(BIN)/pip freeze --all --exclude-editable | grep -v -e '^-e ' -e '^pip==' > constraints.txt

# The documentation site (Sphinx + sphinx-gallery): docs/_build/html/index.html.  -W: a warning
# (a broken reference, a docstring docutils cannot parse) fails the build; --keep-going lists them all.
docs: setup
	$(BIN)/python -m sphinx -q -W --keep-going -b html docs docs/_build/html

# The Blender add-on as an installable zip (out/piste_addon.zip) and the copy the wheel ships.
blender-addon: setup
	$(BIN)/piste blender-addon --out out/piste_addon.zip
	$(BIN)/piste blender-addon --out src/piste/data/blender_addon.zip

clean:
	rm -rf $(VENV) .venv-latest out
