# Everything runs in .venv, created and filled by scripts/bootstrap.sh on first
# use (torch 2.13.0 CPU first, then `pip install -e ".[dev]"`). The stamp file
# .venv/.installed makes later runs skip the install until pyproject.toml changes.

SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DEFAULT_GOAL := help

VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
PYTEST := $(VPY) -m pytest

.PHONY: help demo test test-all test-ray lint venv clean

help:
	@echo "make demo      create .venv, install everything (torch 2.13.0 CPU first), run the main job"
	@echo "make test      create .venv, install everything, run the test suite (not slow)"
	@echo "make test-all  the test suite including slow physics validations"
	@echo "make test-ray  install the [ray] extra and run the Ray tests (RLlib, sweep, reproduce)"
	@echo "make lint      ruff check + ruff format --check"
	@echo "make venv      only create/update .venv"
	@echo "make clean     remove .venv and caches"

$(STAMP): pyproject.toml scripts/bootstrap.sh
	VENV=$(VENV) scripts/bootstrap.sh

venv: $(STAMP)

# The main job (~12 min on 2 cores, measured 2026-11-29; creating the venv first takes
# ~2 min): simulate a serpentine (figure, trace, rerun recording), then train a residual
# PPO briefly, evaluate every policy against the baselines on held-out targets, and write
# the table, plots and rerun recordings (training/demo.py).
DEMO_OUT := runs/demo
demo: $(STAMP)
	$(VENV)/bin/cnt-sim run --preset serpentine --deposit 400 --dt 31 \
		--out $(DEMO_OUT)/serpentine.npz --png $(DEMO_OUT)/serpentine.png --rrd $(DEMO_OUT)/serpentine.rrd
	$(VENV)/bin/cnt-demo --budget-minutes 8 --out $(DEMO_OUT)
	@echo "demo outputs in $(DEMO_OUT): serpentine.png, results/, rrd/ (open with: rerun FILE.rrd)"

# pytest exits 5 when it collects no test; that must fail, not pass silently.
define run_pytest
	rc=0; $(PYTEST) $(1) || rc=$$?; \
	if [[ $$rc -eq 5 ]]; then echo "make: pytest collected no tests (exit 5); failing" >&2; exit 1; fi; \
	exit $$rc
endef

test: $(STAMP)
	@$(call run_pytest,-m "not slow" -q)

test-all: $(STAMP)
	@$(call run_pytest,-q)

RAY_STAMP := $(VENV)/.installed-ray
# the Ray backends of sweep and reproduce (skipped by test and test-all without ray)
RAY_TESTS := tests/test_sweep.py::test_ray_backend_runs_the_same_points \
	tests/test_reproduce.py::test_ray_backend_gives_the_same_points
$(RAY_STAMP): $(STAMP)
	$(VPY) -m pip install -e ".[ray]"
	touch $(RAY_STAMP)

test-ray: $(RAY_STAMP)
	@$(call run_pytest,-q tests/test_rllib.py $(RAY_TESTS))

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
