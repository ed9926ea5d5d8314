# Two entry points (README): `make demo` and `make test`. Both set up .venv first.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: setup setup-blender setup-gltf-validator demo test bench clean mutation mutation-by-hand

$(STAMP): pyproject.toml scripts/setup.sh
	PYTHON=$(PYTHON) bash scripts/setup.sh
	touch $(STAMP)

setup: $(STAMP)

# Blender (bpy 5.0.1, numpy < 2) in an environment of its own, .venv-blender (SPEC 13): the tests of
# the Cycles renderer and the .blend export run in it; `make demo` does not need it. The script is
# idempotent (a stamp file inside .venv-blender) and only warns where bpy cannot be installed.
setup-blender:
	PYTHON=$(PYTHON) bash scripts/setup_blender.sh

# The Khronos glTF-Validator (npm, pure JavaScript) in .node-tools, for the glTF export tests; only
# warns where node/npm are missing (those tests are then skipped with a line saying so).
setup-gltf-validator:
	bash scripts/setup_gltf_validator.sh

demo: $(STAMP)
	$(VENV)/bin/brdffit demo -o out/demo --force

test: $(STAMP) setup-blender setup-gltf-validator
	$(VENV)/bin/python -m pytest -n 2 --dist loadfile -q

bench: $(STAMP)
	$(VENV)/bin/python benchmarks/bench_fit.py

# Mutation testing (slow, not in CI): mutmut 3 over the packages in MUTATE (config: [tool.mutmut]
# in pyproject.toml), without the shared data, at nice 19; prints the score per package and file,
# and the survivors not explained in tests/mutation_equivalents.toml. MUTATE=brdffit.io.npz.* runs
# one file; KEEP=1 keeps mutmut's earlier results (mutants/) instead of starting afresh. Survivors
# and timeouts are then re-run in fresh processes against their package's tests (code run at import
# time is credited by mutmut to one test only): scripts/mutation_recheck.py.
# SAMPLE=400 runs a seeded uniform sample of 400 mutants per package instead (SEED=...; the report
# adds each score's 95 % interval): scripts/mutation_sample.py.
# Measured rates and the full-run estimate: scripts/mutation_scores.md.
MUTATE ?= brdffit.models.* brdffit.fitting.* brdffit.io.*
MUTATION_JOBS ?= 2
SEED ?= 0
mutation: $(STAMP)
	$(VENV)/bin/mutmut --version >/dev/null 2>&1 || $(VENV)/bin/python -m pip install "mutmut==3.8.1"
	$(if $(KEEP),,rm -rf mutants)
	$(if $(SAMPLE),mkdir -p mutants && $(VENV)/bin/python scripts/mutation_sample.py $(SAMPLE) \
	    $(foreach p,$(MUTATE),"$(p)") --seed $(SEED) > mutants/sample.txt)
	VENV=$(VENV) MUTATION_JOBS=$(MUTATION_JOBS) scripts/mutation_run.sh \
	    $(if $(SAMPLE),$$(cat mutants/sample.txt),$(foreach p,$(MUTATE),"$(p)")) || true
	nice -n 19 $(VENV)/bin/python scripts/mutation_recheck.py $(foreach p,$(MUTATE),"$(p)")
	$(VENV)/bin/python scripts/mutation_report.py $(if $(SAMPLE),--sample mutants/sample.txt) \
	    $(foreach p,$(MUTATE),"$(p)")

# Issue 13's deliberate bugs (also outside models/fitting/io), each applied alone to a copy of the
# tree: at least one named test must fail, without the shared data. Prints one line per bug.
mutation-by-hand: $(STAMP)
	$(VENV)/bin/python scripts/mutation_by_hand.py

clean:
	rm -rf $(VENV) .venv-blender out .pytest_cache .hypothesis mutants
