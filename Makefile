# Two entry points (see README): `make demo` and `make test`. Both set everything up first.
.PHONY: setup demo test bench docs clean
PY := .venv/bin/python

setup:
	@bash scripts/setup.sh

# The main demo: a small geogrid pull-out (000 set-up, half-size box, 375 spheres, 50 mm),
# ending in its force-displacement plot results/demo_pullout/pullout_force.png. A second
# `make demo` replaces the demo's own earlier run there (--overwrite: only the files that run
# recorded; a file of yours in the folder stops it, and nothing is removed).
demo: setup
	$(PY) cases/pullout_000.py --smoke --distance 0.05 --snapshots 5 --out results/demo_pullout --overwrite
	@echo "force-displacement plot: results/demo_pullout/pullout_force.png"

test: setup
	$(PY) -m pytest -q --durations=15 tests

bench: setup
	$(PY) bench/throughput.py

# The API reference of cpp_dem (with cpp_dem._core), femcoupling and geogrid_dem from their
# docstrings (MkDocs + mkdocstrings, docs/api.md); a warning or a module that fails to import fails it.
docs: setup
	$(PY) -m mkdocs build --strict --clean
	@echo "API reference: open build/docs/html/index.html"

clean:
	rm -rf build results .pytest_cache
