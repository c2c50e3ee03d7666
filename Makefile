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
# spreads over the processes and hands out first); TEST_WORKERS=0 runs it in this process. Three
# processes on two cores: many tests wait without computing (a server or a browser starting, a
# timeout the test provokes, a child process killed and restarted), and a third process computes
# meanwhile; the computing part alone keeps two cores busy for most of the run
TEST_WORKERS ?= 3

# the suite writes bytecode as Python does by default (__pycache__, ignored by git) even where PYTHONDONTWRITEBYTECODE
# is set: without it each of the processes rewrites and compiles every test module at every run (collection
# 11 s of CPU per process instead of 3.5 s), and every child process compiles the project's modules again
test: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m mypy
	MPLBACKEND=Agg PYTHONDONTWRITEBYTECODE= $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile

lint: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m mypy

bench: $(STAMP)
	for b in benchmarks/*/bench_*.py; do MPLBACKEND=Agg $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) demo-output .pytest_cache
