# siloflow: the two commands of the README are `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
PIP     = $(VENV)/bin/pip
SUDO    = $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: demo test test-fast install install-engine bench clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q -e '.[test]'
	touch $@

install: $(VENV)/.installed install-engine

# LIGGGHTS 3.8 from Debian (pulls Open MPI), and liggghts-doc, whose unmodified tutorials the
# tests run to check `siloflow post` on dumps siloflow did not write; skipped when installed
TUTORIALS = /usr/share/doc/liggghts/examples/LIGGGHTS/Tutorials_public
install-engine:
	@{ command -v liggghts >/dev/null 2>&1 && test -d $(TUTORIALS); } || { \
	  echo "installing LIGGGHTS (apt-get install liggghts liggghts-doc)"; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq liggghts liggghts-doc >/dev/null; }
	@command -v liggghts >/dev/null 2>&1 || { echo "LIGGGHTS is still missing"; exit 1; }

# the main job on the small default case (about 2-3 minutes on 2 cores)
demo: install
	$(VENV)/bin/siloflow run decks/quick.yaml -o runs/quick --force

# every test, the engine tests included
test: install
	$(PY) -m pytest -q

# without the LIGGGHTS runs
test-fast: $(VENV)/.installed
	$(PY) -m pytest -q -m "not engine"

bench: install
	$(PY) benchmarks/wrapper_overhead.py
	$(PY) benchmarks/dump_reader_speed.py
	$(PY) benchmarks/coarse_graining_speed.py

clean:
	rm -rf runs .pytest_cache
