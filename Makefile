# Two entry points (README): `make demo` and `make test`. Both set up .venv first.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: setup demo test bench clean

$(STAMP): pyproject.toml scripts/setup.sh
	PYTHON=$(PYTHON) bash scripts/setup.sh
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/brdffit demo -o out/demo --force

test: $(STAMP)
	$(VENV)/bin/python -m pytest -n 2 --dist loadfile -q

bench: $(STAMP)
	$(VENV)/bin/python benchmarks/bench_fit.py

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
