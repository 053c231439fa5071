# footprint-uq: two entry points, both create .venv on first use.
# make demo: uncertainty maps of a roadside camera under three presets + the paper's left-turn case study
#            (out/demo/report.html, linking out/demo/case-study/report.html).
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-dev
DEMO_STAMP := $(VENV)/.installed

.PHONY: demo test test-quick sysdeps lint bench clean

# Every step says what it does (pip's own progress, not -q): a fresh install takes minutes.
$(BIN)/python:
	@echo "== creating the virtual environment $(VENV) ($(PY))"
	$(PY) -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade --progress-bar on pip

# the demo needs the package and its core dependencies only (numpy, scipy, numba, opencv, matplotlib, ...)
$(DEMO_STAMP): pyproject.toml | $(BIN)/python
	@echo "== installing footprint-uq and its core dependencies into $(VENV) (pip install -e .)"
	$(BIN)/python -m pip install --progress-bar on -e .
	touch $(DEMO_STAMP)

# the tests need the development extras too (pytest, hypothesis, dask, carla, the ASN.1 decoders, ROS 2 bags, ...)
$(STAMP): pyproject.toml | $(BIN)/python
	@echo "== installing footprint-uq with its development extras into $(VENV) (pip install -e '.[dev]')"
	$(BIN)/python -m pip install --progress-bar on -e '.[dev]'
	touch $(STAMP) $(DEMO_STAMP)

demo: $(DEMO_STAMP)
	@echo "== running the demo: uncertainty maps of a roadside camera and the paper's case study -> out/demo/"
	$(BIN)/footprint-uq demo --out out/demo

# numba's on-disk cache: each kernel of the package is keyed on all its kernel sources (_numba_cache.py), so an
# edit never leaves a stale kernel behind; the tests still start from a clean cache, so that every kernel is
# also compiled from scratch once per run.
# The kernels are compiled first, two groups at once (both cores), then two pytest workers share them
# (pytest-xdist; --dist worksteal: a worker that runs out of tests takes some of the other's).
test: $(STAMP) sysdeps
	$(BIN)/ruff check src tests bench
	find src -name '*.nbi' -delete -o -name '*.nbc' -delete
	$(BIN)/footprint-uq warmup --only objects --only points & pid=$$!; \
	  $(BIN)/footprint-uq warmup --only map --only lens && wait $$pid
	$(BIN)/python -m pytest -q -n 2 --dist worksteal --durations=15

# the suite less the tests marked slow (tests/conftest.py SLOW_TESTS and @pytest.mark.slow); keeps numba's cache
# (kernels whose sources changed compile again on first use)
test-quick: $(STAMP)
	$(BIN)/ruff check src tests bench
	$(BIN)/python -m pytest -q -n 2 --dist worksteal -m "not slow"

# chromium (browser tests) and mosquitto (MQTT tests): installed as root with apt-get, else the tests that need
# them are skipped and listed at the end of the run
sysdeps:
	@bash tools/sysdeps.sh

lint: $(STAMP)
	$(BIN)/ruff check src tests bench

bench: $(STAMP)
	$(BIN)/python bench/run.py

clean:
	rm -rf $(VENV) out build src/*.egg-info
