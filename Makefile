# Two commands on a fresh machine: `make run` (the main job) and `make test`; `make docs` builds the site.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# mkdocs-material prints a notice about its successor on every build (not a warning of ours).
# The docs builds are strict and not --quiet: --quiet would hide the warnings --strict fails on.
export NO_MKDOCS_2_WARNING := 1

.PHONY: run test test-lowest demo docs pages bench clean

# constraints.txt: the exact versions that reproduce the study (pyproject.toml holds the ranges)
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet -c constraints.txt -e '.[train,test,docs]'
	# compiling the phase optimiser's kernel once, up front (10-25 s; numba caches it for every later process)
	$(PY) -c "from uavris.physics.phase_opt import compile_optimiser; compile_optimiser()"
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/uavris reproduce --preset quick --out runs/quick

# Every results page of docs/results from this version (resumable: a rerun continues; uavris pages --list)
pages: $(STAMP)
	$(VENV)/bin/uavris pages --jobs 2 --workers 1

demo: $(STAMP)
	$(VENV)/bin/uavris demo

test: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks
	$(VENV)/bin/mkdocs build --strict
	$(PY) -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder

# The lowest numpy pyproject.toml allows, under the physics, environment, oracle and statistics tests: a venv
# whose own numpy (2.3.5) comes before the lock's, every other package the lock's (.ci/run runs it after make test).
LOWEST := .venv-lowest
test-lowest: $(STAMP)
	rm -rf $(LOWEST) && $(PYTHON) -m venv $(LOWEST)
	$(LOWEST)/bin/python -m pip install --quiet --no-deps 'numpy==2.3.5'
	$(PY) -c "import sysconfig; print(sysconfig.get_paths()['purelib'])" > "$$($(LOWEST)/bin/python -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")/zz_lock.pth"
	echo "$(CURDIR)/src" >> "$$($(LOWEST)/bin/python -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")/zz_lock.pth"
	$(LOWEST)/bin/python -c "import numpy; assert numpy.__version__ == '2.3.5', numpy.__version__"
	$(LOWEST)/bin/python -m pytest -q -p no:cacheprovider -m "not slow" tests/test_channel.py tests/test_geometry.py \
		tests/test_reflection.py tests/test_pairing.py tests/test_motion.py tests/test_env.py tests/test_hybrid_env.py \
		tests/test_oracle.py tests/test_stats.py tests/test_claims.py tests/test_regime.py tests/test_oracle_gap.py \
		tests/test_safety.py

docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict

bench: $(STAMP)
	$(PY) -m pip install --quiet -c constraints.txt -e '.[bench]'
	$(PY) benchmarks/env_throughput.py
	$(PY) benchmarks/train_throughput.py
	$(PY) benchmarks/sb3_share.py
	$(PY) benchmarks/dt_throughput.py
	$(PY) benchmarks/oracle_throughput.py
	$(PY) benchmarks/slot_memo.py
	$(PY) benchmarks/cli_parse.py
	$(PY) benchmarks/paper_wallclock.py
	$(PY) benchmarks/reproduce_scaling.py

clean:
	rm -rf $(VENV) runs site
