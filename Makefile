# Two commands on a fresh machine (Python 3.11, pip, make):  `make demo`  and  `make test`.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
export MPLBACKEND ?= Agg

# Headless rendering (mjx-damage render, tests/test_render.py) uses MuJoCo's OSMesa
# backend: software OpenGL from Debian's libosmesa6. The interactive viewer without a
# screen (mjx-damage view --headless, tests/test_viewer.py) runs on Xvfb (Debian's xvfb).
# Installed here when missing and when we can (root with apt-get, as on CI); otherwise
# a note says what to install (tests/test_viewer.py then skips its viewer tests, saying why).
SYSTEM_PACKAGES := libosmesa6 xvfb xdotool
# The suite is compile-bound and XLA compiles on one thread: two pytest workers (one module per
# worker, so module-scoped compiled fixtures compile once) about halve its time on 2 cores
# (≈ 20 min on CI; on a 2-core dev machine 17–20 min with a warm compilation cache, 42 min cold).
TEST_WORKERS ?= 2

.PHONY: demo test test-slow bench install clean system-deps

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $@

system-deps:
	@missing=""; for p in $(SYSTEM_PACKAGES); do \
	  dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -z "$$missing" ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "installing system packages:$$missing"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	else echo "note: headless rendering / the viewer without a screen need:$$missing (sudo apt-get install$$missing)"; fi

install: system-deps $(VENV)/.installed

demo: install
	$(VENV)/bin/mjx-damage demo

test: install
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile

test-slow: install
	$(PY) -m pytest -q -m slow

clean:
	rm -rf $(VENV)
