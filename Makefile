# Two entry points (README): `make demo` and `make test`. Both set up .venv first.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: setup demo test bench clean mutation

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

# Mutation testing (slow, not in CI): mutmut 3 over the packages in MUTATE (config: [tool.mutmut]
# in pyproject.toml), without the shared data; prints the score per package and the survivors.
MUTATE ?= brdffit.models* brdffit.fitting* brdffit.io*
MUTATION_JOBS ?= 2
mutation: $(STAMP)
	$(VENV)/bin/mutmut --version >/dev/null 2>&1 || $(VENV)/bin/python -m pip install "mutmut==3.8.1"
	rm -rf mutants
	BRDFFIT_DATA=/nonexistent $(VENV)/bin/mutmut run --max-children $(MUTATION_JOBS) $(foreach p,$(MUTATE),"$(p)") || true
	$(VENV)/bin/mutmut results --all=True | $(VENV)/bin/python scripts/mutation_report.py $(foreach p,$(MUTATE),"$(p)")

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis mutants
