#!/bin/sh
# Run mutmut on some mutants only, at the lowest CPU priority (others time benchmarks on this machine).
# Usage: scripts/mutation_run.sh GLOB...   e.g. scripts/mutation_run.sh 'brdffit.io.npz.*' 'brdffit.models.ggx.*'
# Naming mutants re-runs them even when mutmut has a result for them; the report is scripts/mutation_report.py.
cd "$(dirname "$0")/.." || exit 2
VENV=${VENV:-.venv}
[ -x "$VENV/bin/mutmut" ] || VENV=/work/main/.venv
# the tests must import the mutated copy in mutants/, never this tree
unset PYTHONPATH
BRDFFIT_DATA=/nonexistent exec nice -n 19 "$VENV/bin/mutmut" run --max-children "${MUTATION_JOBS:-2}" "$@"
