# datmo: two commands on a fresh machine: `make demo`, then `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
DEMO_LOG := sample_logs/hall.mcap

.PHONY: install demo test test-fast lint bench accuracy sample-logs regress regress-update clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --disable-pip-version-check -e '.[dev]'
	touch $(STAMP)

install: $(STAMP) ## create .venv and install datmo (editable) with the dev extras

demo: install ## process the hall sample log and print its report
	$(BIN)/datmo info $(DEMO_LOG)

test: install ## the whole test suite (what CI runs)
	$(BIN)/pytest -q

test-fast: install ## the suite without tests marked slow
	$(BIN)/pytest -q -m "not slow"

lint: install
	$(BIN)/ruff check datmo_cli tests benchmarks

bench: install ## speed figures: scans/s and µs/scan per stage beside plain MCAP read speed
	$(BIN)/python -m benchmarks bench

accuracy: install ## accuracy figures on simulated logs (ground truth) and real data
	$(BIN)/python -m benchmarks accuracy

sample-logs: install ## regenerate sample_logs/ bit for bit
	PATH="$(CURDIR)/$(BIN):$$PATH" bash sample_logs/make.sh

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
