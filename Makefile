# datmo: two commands on a fresh machine: `make demo`, then `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
DEMO_LOG := sample_logs/hall.mcap
# pytest-xdist workers of make test (auto: one per core); each test file runs whole on one worker, so its
# module-scoped fixtures (a `datmo run` shared by its tests) run once
WORKERS ?= auto
XDIST := -n $(WORKERS) --dist loadfile

.PHONY: help install demo check test test-suite test-unit test-fast test-nojit test-no-avx512 test-numba-plain lint typecheck bench accuracy sample-logs regress regress-update run-digests clean legs-model lock py313

$(STAMP): pyproject.toml datmo_cli/__init__.py constraints.txt
	$(PYTHON) -m venv $(VENV)
	@# the distribution was called datmo before it became datmo-cli: an older venv drops the old name
	$(BIN)/pip uninstall --quiet --disable-pip-version-check -y datmo 2>/dev/null || true
	@# constraints.txt: the versions CI tests (make lock refreshes it on purpose)
	$(BIN)/pip install --quiet --disable-pip-version-check -c constraints.txt -e '.[dev]'
	@# byte-compile datmo's own modules now: an editable install leaves that to each import, and where
	@# PYTHONDONTWRITEBYTECODE is set (as in many containers) every process would compile them again
	$(BIN)/python -m compileall -q datmo_cli
	touch $(STAMP)

help: ## list the targets, each with what it does
	@grep -E '^[a-z0-9-]+:.*## ' $(MAKEFILE_LIST) | sed -E 's/^([a-z0-9-]+):.*## (.*)$$/\1\t\2/' | \
		awk -F'\t' '{ printf "  make %-15s %s\n", $$1, $$2 }'

install: $(STAMP) ## create .venv and install datmo (editable) with the dev extras

demo: install ## process the hall sample log: segment, features, track; print the report and draw out/hall.png
	$(BIN)/datmo run $(DEMO_LOG) -o out --force --plot

test: lint typecheck test-suite test-nojit test-no-avx512 test-numba-plain ## lint, typecheck, the whole suite, test-nojit, test-no-avx512, test-numba-plain (CI runs it as make check: .ci/run)

check: test ## another name for make test

test-suite: install ## the whole test suite alone, in parallel (pytest-xdist, WORKERS=auto)
	$(BIN)/pytest -q $(XDIST)

test-unit: install ## the fast inner loop: the tests marked unit and not slow, in parallel (under a minute)
	$(BIN)/pytest -q $(XDIST) -m "unit and not slow"

test-fast: install ## the suite without the tests marked slow, in parallel
	$(BIN)/pytest -q $(XDIST) -m "not slow"

KERNEL_COVERAGE = 80  # percent of the kernel modules' lines that test-nojit must cover (it fails below)

test-nojit: install ## the kernel reference checks (tests/kernel_checks.py) with the kernels as plain Python (NUMBA_DISABLE_JIT=1); fails under KERNEL_COVERAGE % of the kernel modules' lines
	NUMBA_DISABLE_JIT=1 $(BIN)/pytest -q $(XDIST) -m "kernels and not slow" \
		$$($(BIN)/python tests/kernel_modules.py) --cov-report=term --cov-fail-under=$(KERNEL_COVERAGE)

test-no-avx512: install ## the output fingerprints again with numpy's AVX-512 code switched off (a no-op on a CPU without it)
	NPY_DISABLE_CPU_FEATURES="$$($(BIN)/python tests/avx512_features.py)" $(BIN)/pytest -q -p no:xdist \
		tests/test_output_digests.py -k stored_fingerprints

test-numba-plain: install ## the kernel reference checks again with the kernels loaded numba's own way (DATMO_NUMBA_LIGHT=0: none of numba_light's patches), so that path cannot rot
	DATMO_NUMBA_LIGHT=0 $(BIN)/pytest -q $(XDIST) -m "kernels and not slow"

lint: install ## ruff check and ruff format --check on the whole repository
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: install ## mypy on the package (its tiers: [tool.mypy] in pyproject.toml)
	$(BIN)/mypy datmo_cli

bench: install ## speed figures: scans/s and µs/scan per stage beside plain MCAP read speed; a plain install's size
	$(BIN)/python -m benchmarks bench

accuracy: install ## accuracy figures on simulated logs (ground truth) and real data
	$(BIN)/python -m benchmarks accuracy

regress: install ## datmo run + evaluate on every sample log, compared with tests/regress_baseline.json
	$(BIN)/python -m benchmarks.regress

regress-update: install ## rewrite tests/regress_baseline.json from the current figures (review the diff)
	$(BIN)/python -m benchmarks.regress --update

run-digests: install ## rewrite tests/run_digests.json, the fingerprints of datmo run's outputs on the sample logs (say why in the commit)
	$(BIN)/python tests/run_cases.py

legs-model: install ## retrain the packaged leg model (datmo_cli/perception/models/legs.npz) from ../shared/data/legtracker
	$(BIN)/datmo train-legs --positive $(sort $(wildcard ../shared/data/legtracker/positive_*_extracted.bag)) \
		--negative ../shared/data/legtracker/negative_2.bag --with-simulated \
		-o datmo_cli/perception/models/legs.npz --force

sample-logs: install ## regenerate sample_logs/ bit for bit
	PATH="$(CURDIR)/$(BIN):$$PATH" bash sample_logs/make.sh

py313: ## a plain install on Python 3.13 (Debian 13's, in a chroot made with debootstrap; root) runs datmo info and datmo run on the hall log
	bash .ci/python313.sh

lock: ## refresh constraints.txt to the newest versions pyproject.toml allows, in a new venv; prints what moved
	rm -rf .venv-lock && $(PYTHON) -m venv .venv-lock
	.venv-lock/bin/pip install --quiet --disable-pip-version-check -e '.[dev]'
	.venv-lock/bin/pip freeze --exclude-editable > constraints.txt.new
	@diff constraints.txt constraints.txt.new | grep '^[<>]' || echo "nothing moved"
	mv constraints.txt.new constraints.txt && rm -rf .venv-lock
	@echo "constraints.txt refreshed: run make test, then commit it with what moved"

clean: ## remove out/, .venv and the build and cache folders
	rm -rf out $(VENV) build *.egg-info .pytest_cache .ruff_cache .mypy_cache .coverage
