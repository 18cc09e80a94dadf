# Two entry points (see README): `make demo` and `make test`. Both set everything up first.
.PHONY: setup demo test bench clean
PY := .venv/bin/python

setup:
	@bash scripts/setup.sh

demo: setup
	$(PY) cases/deposition.py --out results/deposition

test: setup
	$(PY) -m pytest -q tests

bench: setup
	$(PY) bench/throughput.py

clean:
	rm -rf build results .pytest_cache
