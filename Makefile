# Two commands on a fresh machine: `make run` (the main job) and `make test`; `make docs` builds the site.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# mkdocs-material prints a notice about its successor on every build (not a warning of ours).
# The docs builds are strict and not --quiet: --quiet would hide the warnings --strict fails on.
export NO_MKDOCS_2_WARNING := 1

.PHONY: run test demo docs bench clean

# constraints.txt: the exact versions that reproduce the study (pyproject.toml holds the ranges)
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet -c constraints.txt -e '.[train,test,docs]'
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/uavris reproduce --preset quick --out runs/quick

demo: $(STAMP)
	$(VENV)/bin/uavris demo

test: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks
	$(VENV)/bin/mkdocs build --strict
	$(PY) -m pytest -q -n 2 --dist loadfile

docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict

bench: $(STAMP)
	$(PY) -m pip install --quiet -c constraints.txt -e '.[bench]'
	$(PY) benchmarks/env_throughput.py
	$(PY) benchmarks/train_throughput.py
	$(PY) benchmarks/sb3_share.py
	$(PY) benchmarks/dt_throughput.py
	$(PY) benchmarks/oracle_throughput.py
	$(PY) benchmarks/paper_wallclock.py
	$(PY) benchmarks/reproduce_scaling.py

clean:
	rm -rf $(VENV) runs site
