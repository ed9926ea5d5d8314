#!/bin/sh
# Run mutmut on some mutants only, at the lowest CPU priority (others time benchmarks on this machine).
# Usage: scripts/mutation_run.sh GLOB...   e.g. scripts/mutation_run.sh 'brdffit.io.npz.*' 'brdffit.models.ggx.*'
# Naming mutants re-runs them even when mutmut has a result for them; the report is scripts/mutation_report.py.
cd "$(dirname "$0")/.." || exit 2
VENV=${VENV:-.venv}
[ -x "$VENV/bin/mutmut" ] || VENV=/work/main/.venv
# the tests must import the mutated copy in mutants/, never this tree
unset PYTHONPATH
# brdffit's disk cache finds a compiled program by the source's hash, and mutmut's copy is one source
# for every mutant (MUTANT_UNDER_TEST picks one at run time): with it on, every mutant ran the
# first program kept (seen: a ggx mutant fitted the unmutated model). JAX's own cache is keyed by
# the compiled code, so a mutant that leaves a program as it was loads it instead of compiling.
export BRDFFIT_CACHE=off JAX_COMPILATION_CACHE_DIR="$PWD/mutants/.jax-cache" \
    JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS=0 JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES=0
BRDFFIT_DATA=/nonexistent exec nice -n 19 "$VENV/bin/mutmut" run --max-children "${MUTATION_JOBS:-2}" "$@"
