# impactlab: `make demo` and `make test` each create .venv and install the project first.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test lint venv bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,report,station,batch]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	MPLBACKEND=Agg $(PY) -m acquisition demo --out demo-output

# the suite on TEST_WORKERS processes (pytest-xdist; one test file stays on one process, so a
# module's shared fixture is made once, except the heavy independent tests that tests/conftest.py
# spreads over both processes and hands out first); TEST_WORKERS=0 runs it in this process
TEST_WORKERS ?= 2

# the suite's bytecode (its assertion-rewritten test modules and every module its child processes import) is kept
# under .pytest_cache/, not beside the sources, even where PYTHONDONTWRITEBYTECODE is set: each of the two processes
# otherwise compiles and rewrites every test module at every run (8 of its 11 s of collection)
TEST_PYCACHE := $(CURDIR)/.pytest_cache/pycache

test: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m mypy
	MPLBACKEND=Agg PYTHONDONTWRITEBYTECODE= PYTHONPYCACHEPREFIX=$(TEST_PYCACHE) $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile

lint: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m mypy

bench: $(STAMP)
	for b in benchmarks/*/bench_*.py; do MPLBACKEND=Agg $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) demo-output .pytest_cache
