# warpsky: two commands on a fresh machine.
#   make demo   render usd_scenes/cumulus.usda to out/cumulus.0001.exr (+ PNG preview)
#   make test   run the test suite on the CPU
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed-$(shell cat pyproject.toml | cksum | cut -d' ' -f1)

.PHONY: demo test lint bench venv data clean help stratocumulus cumulus-wind

help:
	@echo "make demo   - install into $(VENV), generate sample data, render the demo cumulus to out/"
	@echo "make test   - install into $(VENV) and run the tests on the CPU"
	@echo "make bench  - run benchmarks/bench_single_scatter.py (cuda too when present)"
	@echo "make lint   - ruff"

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev,compare]"
	rm -f $(VENV)/.installed-*
	touch $@

data/cumulus.nvdb: tools/make_cumulus.py $(STAMP)
	$(PY) tools/make_cumulus.py --out data

data: data/cumulus.nvdb

demo: $(STAMP) data/cumulus.nvdb
	$(VENV)/bin/warpsky render usd_scenes/cumulus.usda out/cumulus.####.exr --frames 1 --png

test: $(STAMP)
	$(PY) -m pytest -q

lint: $(STAMP)
	$(VENV)/bin/ruff check warpsky tests tools benchmarks

bench: $(STAMP) data/cumulus.nvdb
	$(PY) benchmarks/bench_single_scatter.py

cumulus-wind: $(STAMP) data/cumulus.nvdb
	$(VENV)/bin/warpsky render usd_scenes/cumulus_wind.usda out/cumulus_wind.####.exr --frames 1:48 --png

stratocumulus: $(STAMP)
	$(PY) tools/make_stratocumulus.py --out data --render out

clean:
	rm -rf out data .pytest_cache
