# Two entry points (see README): `make demo` and `make test`. Both set everything up first.
.PHONY: setup demo demo-pullout test bench docs wheel clean
PY := .venv/bin/python

setup:
	@bash scripts/setup.sh

# The main demo: the headline, 002's prestressed reinforced-soil element driven by the FEM
# (a footing on a geogrid-reinforced fill): RE against PRS on two seeds at smoke size, loaded
# slowly and measured at rest (about 2 min after set-up), ending in its findings table
# (results/demo_002/report.md) and its figures (results/demo_002/detailed_s1_views.png, _grid,
# _rose). A second `make demo` replaces the demo's own earlier run there (--overwrite: only
# the files that run recorded).
demo: setup
	$(PY) cases/prs_element_002.py --smoke --workers 2 --out results/demo_002 --overwrite
	@echo "findings: results/demo_002/report.md; figures: results/demo_002/detailed_s1_views.png"

# The DEM-only demo: a small geogrid pull-out (000 set-up, half-size box, 375 spheres, 50 mm),
# ending in its force-displacement plot results/demo_pullout/pullout_force.png.
demo-pullout: setup
	$(PY) cases/pullout_000.py --smoke --distance 0.05 --snapshots 5 --out results/demo_pullout --overwrite
	@echo "force-displacement plot: results/demo_pullout/pullout_force.png"

# The suite runs in TEST_JOBS processes (pytest-xdist; a file's tests stay together, so its
# fixtures run once), each test on one OpenMP thread unless it asks for more; waiting OpenMP
# threads sleep instead of spinning, so a two-thread test does not starve the other process.
TEST_JOBS ?= 2
test: setup
	OMP_NUM_THREADS=1 OMP_WAIT_POLICY=passive $(PY) -m pytest -q -n $(TEST_JOBS) --dist loadfile --durations=25 tests

# A wheel of the project (cpp_dem built, femcoupling and geogrid_dem) in $(DIST), for machines
# of this kind (Linux x86-64, Python 3.12): `pip install dist/geogrid_dem-*.whl` into any venv,
# no compiler needed there (docs/start_here.md, "Install"). The build reuses the editable
# install's build folder.
DIST ?= dist
wheel: setup
	$(PY) -m pip wheel -q --no-build-isolation --no-deps -w $(DIST) . \
	  -Ccmake.define.CPP_DEM_GEOGRID=ON
	@ls $(DIST)/geogrid_dem-*.whl

bench: setup
	$(PY) bench/throughput.py

# One site: the guide (docs/*.md, in the order of docs/start_here.md) and the API reference of
# cpp_dem (with cpp_dem._core), femcoupling and geogrid_dem from their docstrings (MkDocs +
# mkdocstrings, docs/api.md); a warning or a module that fails to import fails it.
docs: setup
	$(PY) -m mkdocs build --strict --clean
	@echo "The site (guide and API reference): open build/docs/html/index.html"

# Every marked results table of the docs rewritten from its data file (docs/developing.md,
# "Adding a results table"); the suite checks them (tests/test_docs_tables.py).
docs-tables:
	$(PY) scripts/docs_tables.py render docs/*.md

clean:
	rm -rf build results .pytest_cache
